"""Rig-log and input-file headers name their units, parsed by pint and converted to SI
(trackmj.results.measured): units beyond SI (psi, lbf, in, ms, bar, L/min, g0) converted
with hand-written constants, unknown or misfitting units refused naming the file and the
column, columns naming no quantity ignored and listed, the log identified by its SHA-256.

Every log here is CSV text written by hand; the constants are the definitions (1 psi =
6894.757293168 Pa, 1 lbf = 4.4482216152605 N, 1 in = 0.0254 m, 1 US gal = 231 in³)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest

from trackmj.ports import COLUMN_UNITS
from trackmj.results.measured import input_signal, load_measured, read_trace, si_name
from trackmj.validator import ParameterError

PSI_PA = 6894.757293168
LBF_N = 4.4482216152605
INCH_M = 0.0254
US_GALLON_M3 = 231 * INCH_M**3
STANDARD_GRAVITY = 9.80665
SCENARIO = Path(__file__).parent / "data" / "steps_short.toml"

RIG_CSV = """\
t [ms],p_head [psi],tension [lbf],stroke [in],valve_mode
0,1000,2000,2.0,0
1,1500,2500,2.5,1
2,2000,3000,3.0,1
3,2500,3500,3.5,0
4,3000,4000,4.0,-1
5,3500,4500,4.5,0
"""
"""A rig log in US units, a row per millisecond, each signal linear in time."""


def write(tmp: Path, text: str, name: str = "rig.csv") -> Path:
    path = tmp / name
    path.write_text(text)
    return path


def test_psi_lbf_inch_and_milliseconds_are_converted_to_si(tmp_path):
    trace = read_trace(write(tmp_path, RIG_CSV))
    np.testing.assert_allclose(trace.t_s, [0.0, 0.001, 0.002, 0.003, 0.004, 0.005])
    c = trace.columns
    assert set(c) == {"p_head_Pa", "tension_N", "stroke_m", "valve_mode"}
    np.testing.assert_allclose(c["p_head_Pa"][:2], [1000 * PSI_PA, 1500 * PSI_PA], rtol=1e-12)
    np.testing.assert_allclose(c["tension_N"][:2], [2000 * LBF_N, 2500 * LBF_N], rtol=1e-12)
    np.testing.assert_allclose(c["stroke_m"][:2], [2.0 * INCH_M, 2.5 * INCH_M], rtol=1e-12)
    np.testing.assert_array_equal(c["valve_mode"], [0, 1, 1, 0, -1, 0])
    assert trace.headers["p_head_Pa"] == "p_head [psi]" and trace.ignored == ()


def test_suffix_spellings_convert_as_their_bracket_forms(tmp_path):
    text = ("t_min,p_rod_bar,q_supply_L_min,q_supply_ref [gal/min],stroke_velocity_mm_s,"
            "chassis_acc_z_g0,tension_ref_kN\n"
            "0,100,60,1,250,0.5,12\n"
            "0.001,110,30,2,-250,1.0,13\n")
    trace = read_trace(write(tmp_path, text))
    c = trace.columns
    np.testing.assert_allclose(trace.t_s, [0.0, 0.06])
    np.testing.assert_allclose(c["p_rod_Pa"], [100e5, 110e5])
    np.testing.assert_allclose(c["q_supply_m3_s"], [1e-3, 0.5e-3])      # 60 L/min = 1 L/s
    np.testing.assert_allclose(c["stroke_velocity_m_s"], [0.25, -0.25])
    np.testing.assert_allclose(c["chassis_acc_z_m_s2"], [0.5 * STANDARD_GRAVITY,
                                                         STANDARD_GRAVITY])
    np.testing.assert_allclose(c["tension_ref_N"], [12e3, 13e3])
    # q_supply_ref names no quantity of the run: ignored, listed
    assert trace.ignored == ("q_supply_ref [gal/min]",)
    assert si_name("q_supply [gal/min]") == ("q_supply_m3_s", pytest.approx(US_GALLON_M3 / 60))


@pytest.mark.parametrize(("header", "words"), [
    ("tension_kNm", ["unit 'kNm'", "is not a force", "tension_N needs a unit of force"]),
    ("tension [psi]", ["unit 'psi'", "a pressure", "is not a force"]),
    ("p_head_N", ["unit 'N'", "is not a pressure", "p_head_Pa needs a unit of pressure"]),
    ("tension [furlongs]", ["unit 'furlongs'", "is not a force"]),
    ("tension [kNewtons]", ["unit 'kNewtons' is not a unit pint knows"]),
    ("stroke", ["names no unit", "stroke_m needs a unit of length"]),
    ("valve_mode [bar]", ["valve_mode is dimensionless"]),
])
def test_a_quantity_in_an_unknown_or_misfitting_unit_is_refused(tmp_path, header, words):
    path = write(tmp_path, f"t_s,{header}\n0.0,1.0\n0.001,2.0\n")
    with pytest.raises(ParameterError) as info:
        read_trace(path)
    message = str(info.value)
    assert message.startswith(f"rig.csv column {header!r}: "), message
    assert all(w in message for w in words), message


def test_columns_naming_no_quantity_are_ignored_and_listed_even_with_text(tmp_path):
    text = ("t_s,temperature [degC],comment,engine_rpm,p_head_MPa\n"
            "0.001,40.5,start,1800,5.0\n"
            "0.002,40.6,\"valve, opened\",1810,5.5\n"
            "0.003,40.7,,1820,6.0\n")
    path = write(tmp_path, text)
    log = load_measured(path, 0.003, list(COLUMN_UNITS))
    assert log.ignored == ("temperature [degC]", "comment", "engine_rpm")
    assert log.used == {"p_head_Pa": "p_head_MPa"}
    np.testing.assert_allclose(log.columns["t_s"], [0.001, 0.002, 0.003])
    np.testing.assert_allclose(log.columns["p_head_Pa"], [5.0e6, 5.5e6, 6.0e6])
    record = log.record()
    assert record == {"file": "rig.csv", "sha256": log.sha256,
                      "columns_used": {"p_head_Pa": "p_head_MPa"},
                      "columns_ignored": ["temperature [degC]", "comment", "engine_rpm"],
                      "missing_samples": {}}


def test_text_in_a_quantity_column_is_refused(tmp_path):
    path = write(tmp_path, "t_s,tension_kN\n0.001,12\n0.002,high\n")
    with pytest.raises(ParameterError, match=r"rig\.csv column 'tension_kN': holds string, "
                                             "not numbers"):
        read_trace(path)


def test_a_log_of_ignored_columns_only_is_refused_naming_them(tmp_path):
    path = write(tmp_path, "t_s,hitch_kN,oil [degC]\n0.001,1,40\n0.002,1,40\n")
    with pytest.raises(ParameterError, match=r"rig\.csv: no column to compare besides 't_s' "
                                             r"\(ignored: hitch_kN, oil \[degC\]\)"):
        load_measured(path, 0.002, list(COLUMN_UNITS))


def test_the_log_record_names_the_file_by_its_bytes(tmp_path):
    a = write(tmp_path, RIG_CSV, "a.csv")
    b = write(tmp_path, RIG_CSV.replace("2500,3500,3.5", "2500,3501,3.5"), "b.csv")
    log_a = load_measured(a, 0.005, list(COLUMN_UNITS))
    log_b = load_measured(b, 0.005, list(COLUMN_UNITS))
    assert log_a.sha256 == hashlib.sha256(a.read_bytes()).hexdigest()
    assert log_b.sha256 == hashlib.sha256(b.read_bytes()).hexdigest()
    assert log_a.sha256 != log_b.sha256
    assert log_a.file == "a.csv" and log_a.used == {
        "p_head_Pa": "p_head [psi]", "tension_N": "tension [lbf]", "stroke_m": "stroke [in]",
        "valve_mode": "valve_mode"}
    # on the run's 1 ms grid from the end of the first step; linear in time in the file
    np.testing.assert_allclose(log_a.columns["t_s"], [0.001, 0.002, 0.003, 0.004, 0.005])
    np.testing.assert_allclose(log_a.columns["tension_N"],
                               LBF_N * np.array([2500, 3000, 3500, 4000, 4500]), rtol=1e-12)


def test_the_runs_own_columns_are_the_quantities_of_its_log(tmp_path):
    """A --channels all column is a quantity of a run that records it; of another run it is
    ignored; a quantity the run does not record is refused."""
    path = write(tmp_path, "t_s,p_head_L [psi],p_head [psi]\n0.001,1,2\n0.002,1,2\n")
    every = load_measured(path, 0.002, [*COLUMN_UNITS, "p_head_L_Pa"])
    np.testing.assert_allclose(every.columns["p_head_L_Pa"], [PSI_PA, PSI_PA], rtol=1e-12)
    default = load_measured(path, 0.002, list(COLUMN_UNITS))
    assert default.ignored == ("p_head_L [psi]",) and set(default.used) == {"p_head_Pa"}
    with pytest.raises(ParameterError, match=r"rig\.csv column 'p_head \[psi\]': p_head_Pa "
                                             "is not a column of the run"):
        load_measured(path, 0.002, ["t_s", "tension_N"])


HAND_FACTORS = {("s", "ms"): 1e-3, ("s", "min"): 60.0, ("N", "kN"): 1e3, ("N", "lbf"): LBF_N,
                ("Pa", "kPa"): 1e3, ("Pa", "MPa"): 1e6, ("Pa", "bar"): 1e5, ("Pa", "psi"): PSI_PA,
                ("m", "mm"): 1e-3, ("m", "in"): INCH_M, ("m", "ft"): 12 * INCH_M,
                ("m/s", "mm/s"): 1e-3, ("m/s", "in/s"): INCH_M,
                ("m^3/s", "L/min"): 1e-3 / 60, ("m^3/s", "gal/min"): US_GALLON_M3 / 60,
                ("m/s^2", "g0"): STANDARD_GRAVITY, ("J", "kJ"): 1e3, ("1", "-"): 1.0,
                ("1", "%"): 0.01}
"""Every unit the messages and the README offer as an example, by its definition."""


def test_every_unit_offered_as_an_example_converts_by_its_definition():
    from trackmj.results.measured import UNIT_EXAMPLES, si_factor

    offered = {(si, unit) for si, (_, units) in UNIT_EXAMPLES.items()
               for unit in units.split(", ") if unit != si}
    assert offered == set(HAND_FACTORS)
    for (si, unit), factor in HAND_FACTORS.items():
        assert si_factor(unit, si) == pytest.approx(factor, rel=1e-12), (si, unit)


def test_every_run_column_reads_as_itself():
    for name in COLUMN_UNITS:
        assert si_name(name) == (name, 1.0), name


def test_input_files_take_any_name_in_a_unit_of_the_inputs_dimension(tmp_path):
    path = write(tmp_path, "time [ms],speed [in/s]\n0,0\n1000,59.055118110236\n", "v.csv")
    signal = input_signal(path, None, "m_s", "track speed")
    assert signal.column == "speed [in/s]"
    assert float(signal(1.0)) == pytest.approx(1.5, rel=1e-12)
    assert float(signal(0.5)) == pytest.approx(0.75, rel=1e-12)
    bad = write(tmp_path, "t_s,F_ref [psi]\n0,1\n3,1\n", "ref.csv")
    with pytest.raises(ParameterError) as info:
        input_signal(bad, None, "N", "reference F_ref")
    assert str(info.value).startswith("ref.csv column 'F_ref [psi]' (reference F_ref): unit "
                                      "'psi'"), str(info.value)
    assert "reference F_ref needs a unit of force" in str(info.value)


def test_calibration_log_records_its_columns_and_refuses_an_unknown_unit(tmp_path):
    from trackmj.study.calibrate import load_log

    t = np.arange(1, 6)
    rows = "\n".join(f"{k},{700 + k},0,{k % 2},ok" for k in t)
    path = write(tmp_path, f"t [ms],p_head [psi],p_supply_bar,valve_mode,note\n{rows}\n")
    log = load_log(path, 0.005)
    np.testing.assert_allclose(log.channels["p_head_Pa"], (700 + t) * PSI_PA, rtol=1e-12)
    assert log.record() == {"file": "rig.csv", "sha256": hashlib.sha256(
        path.read_bytes()).hexdigest(), "columns_used": {"valve_mode": "valve_mode",
                                                         "p_head_Pa": "p_head [psi]"},
        "columns_ignored": ["note", "p_supply_bar"], "missing_samples": {}}
    path.write_text(path.read_text().replace("p_head [psi]", "p_head [psix]"))
    with pytest.raises(ParameterError, match=r"rig\.csv column 'p_head \[psix\]': unit 'psix' "
                                             "is not a unit pint knows"):
        load_log(path, 0.005)


def test_cli_refuses_an_unknown_unit_with_exit_2_naming_the_column(tmp_path, capsys):
    from trackmj.cli.main import main

    log = write(tmp_path, "t_s,tension_kNm,p_head_Pa\n0.001,12,5e6\n0.5,12,5e6\n")
    # the header is refused before anything runs: the scenario's own duration costs nothing
    code = main(["run", str(SCENARIO), "--measured", str(log), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "rig.csv column 'tension_kNm': unit 'kNm'" in err and "is not a force" in err, err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize(("header", "name", "factor"), [
    ("tension (kN)", "tension_N", 1e3),            # parentheses as brackets
    ("Tension [lbf]", "tension_N", LBF_N),         # a name in capitals
    ("P_HEAD_psig", "p_head_Pa", PSI_PA),          # psig: gauge, as the run's pressures
    ("p_head [barg]", "p_head_Pa", 1e5),
    ("q_supply (gpm)", "q_supply_m3_s", US_GALLON_M3 / 60.0),
])
def test_rig_spellings_of_names_and_units(tmp_path, header, name, factor):
    trace = read_trace(write(tmp_path, f"Time (s),{header}\n0,2\n1,3\n"))
    np.testing.assert_allclose(trace.t_s, [0.0, 1.0])
    np.testing.assert_allclose(trace.columns[name], [2 * factor, 3 * factor], rtol=1e-12)


def test_one_letter_names_in_capitals_are_not_the_runs(tmp_path):
    """``T`` and ``U`` are usually a temperature and a voltage: ignored, not read as the
    time and the opening (and refused for their units)."""
    trace = read_trace(write(tmp_path, "t_s,T [degC],U [V]\n0,40,12\n1,41,12\n"))
    assert trace.columns == {} and trace.ignored == ("T [degC]", "U [V]")


def test_an_absolute_pressure_is_refused_naming_why(tmp_path):
    path = write(tmp_path, "t_s,p_head [psia]\n0,100\n1,110\n")
    with pytest.raises(ParameterError, match=r"rig.csv column 'p_head \[psia\]'.*absolute"):
        read_trace(path)


@pytest.mark.parametrize(("text", "encoding"), [
    ("t [ms];p_head [bar];Öltemp [°C];valve_mode\n0;1,5;40,1;0\n1;2,5;40,2;1\n", "cp1252"),
    ("t [ms]\tp_head [bar]\tvalve_mode\n0\t1,5\t0\n1\t2,5\t1\n", "utf-8"),
    ("t [ms];p_head [bar];valve_mode\n0;1.5;0\n1;2.5;1\n", "utf-8"),
    ("t [ms], p_head [bar] , valve_mode\n0, 1.5, 0\n1, 2.5, 1\n", "latin-1"),
])
def test_european_and_spaced_csv_dialects_read_as_the_plain_one(tmp_path, text, encoding):
    """A Windows-1252 header with ';' and decimal commas, tabs, ';' with decimal points and
    spaces around headers: the same bar values and valve modes as a plain CSV."""
    path = tmp_path / "rig.csv"
    path.write_bytes(text.encode(encoding))
    trace = read_trace(path)
    np.testing.assert_allclose(trace.t_s, [0.0, 0.001])
    np.testing.assert_allclose(trace.columns["p_head_Pa"], [1.5e5, 2.5e5], rtol=1e-12)
    np.testing.assert_array_equal(trace.columns["valve_mode"], [0, 1])
    assert trace.ignored == (("Öltemp [°C]",) if "Öltemp" in text else ())


def test_parquet_units_from_field_metadata_and_the_studys_symbols(tmp_path):
    """A Parquet column named without a unit takes its field's unit metadata (kN, ms);
    F_ten is the study's symbol for the tensioner force."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pa.table({"t": [0.0, 1.0], "F_ten": [12.0, 13.0]}).cast(pa.schema([
        pa.field("t", pa.float64(), metadata={"unit": "ms"}),
        pa.field("F_ten", pa.float64(), metadata={"unit": "kN"})]))
    pq.write_table(table, tmp_path / "rig.parquet")
    trace = read_trace(tmp_path / "rig.parquet")
    np.testing.assert_allclose(trace.t_s, [0.0, 0.001])
    np.testing.assert_allclose(trace.columns["tension_N"], [12e3, 13e3])
    assert trace.headers["tension_N"] == "F_ten [kN]"
