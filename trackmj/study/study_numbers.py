"""The study's published figures, the numbers the report's claims are judged against.

Source: :data:`STUDY`, its results as the paper states them (tables and text). They are data
from the paper, printed beside ours for comparison only; nothing in trackmj is tuned toward
them. The paper names its architectures TP (tri-platform co-simulation), DP-A and DP-B; the
tables below key them by the names trackmj registers its counterparts under
(:data:`STUDY_REFERENCE`, :data:`STUDY_REDUCED`), and its conditions by the scenario names
W1-W5. Forces [N], pressures [Pa], times [s], energies [kJ] as the paper gives them,
percentages [%].
"""

from __future__ import annotations

STUDY = ("Ding et al., \"Simulation Method for Hydraulic Tensioning Systems in Tracked "
         "Vehicles Using Simulink-AMESim-RecurDyn\", Actuators 2025, 14(12), 615")
"""The study the report answers, as cited in report.md."""

STUDY_REFERENCE = "tp"
"""The study's TP, the key of its reference architecture in the tables below (trackmj's
counterpart: :data:`trackmj.sim.registry.REFERENCE_ARCHITECTURE`)."""
STUDY_REDUCED = ("dp-a", "dp-b")
"""The study's DP-A (hydraulics on an equivalent idler) and DP-B (an ideal force source),
keys of the tables below and the names of trackmj's counterparts."""

STUDY_RMSE = {"W1": {"tp": 420.0, "dp-a": 1150.0, "dp-b": 920.0},
              "W2": {"tp": 860.0, "dp-a": 1640.0, "dp-b": 1270.0},
              "W5": {"tp": 790.0, "dp-a": 1750.0, "dp-b": 1280.0}}
"""The study's tension RMSE [N] per condition and architecture (its results tables)."""
STUDY_FLUCTUATION = {"W2": {"tp": 1300.0, "dp-a": 2600.0, "dp-b": 2100.0},
                     "W5": {"tp": 1100.0, "dp-a": 2800.0, "dp-b": 2000.0}}
"""The study's tension fluctuation ±[N]."""
STUDY_DISTURBANCE = {"W3": {"tp": (1600.0, 2.4), "dp-a": (3800.0, 4.1), "dp-b": (2700.0, 3.3)},
                     "W4": {"tp": (900.0, 1.8), "dp-a": (2600.0, 3.5), "dp-b": (1900.0, 2.7)}}
"""The study's response to a disturbance: (peak error [N], time back [s]); W3 its overshoot
and settling time, W4 its dip and recovery time."""

STUDY_ENERGY_KJ = {"W1": (82.4, 95.8, 91.7), "W2": (83.1, 97.2, 93.0), "W3": (83.1, 97.2, 93.0),
                   "W4": (80.3, 96.1, 92.4), "W5": (81.5, 98.2, 93.6)}
"""The study's "energy consumption" [kJ] (TP, DP-A, DP-B); undefined in the study."""
STUDY_ENERGY_SAVING_PCT = (12.0, 17.0)
"""How much less energy the study's TP uses than its DP [%] (low, high)."""

STUDY_NMPC_GAIN_PCT = {"lmpc": (30.0, 45.0), "pid": (40.0, 55.0)}
"""How much lower the study's NMPC tension RMSE is than each baseline controller's on TP [%]
(low, high), keyed by trackmj's name of the baseline."""

STUDY_W3_PRESSURE_LOWER_PA = (0.9e6, 1.2e6)
"""How much lower TP's peak head pressure is than DP's in W3 [Pa] (low, high)."""
STUDY_W3_FEWER_SWITCHES_PCT = 21.0
"""How many fewer valve switches TP makes than DP in W3 [%] (the study: "~21 %")."""
STUDY_W2_BODY_ACC_LOWER_PCT = (19.0, 27.0)
"""How much lower TP's body acceleration RMS in the 8-12 Hz mode is than DP's in W2 [%]."""

STUDY_REAL_TIME_FACTOR = (0.4, 0.55)
"""The study's TP speed: simulated over wall time (low, high) [-]."""
STUDY_REAL_TIME_FACTOR_MID = 0.475
"""The middle of :data:`STUDY_REAL_TIME_FACTOR`, what ours is stated as a multiple of [-]."""
STUDY_STEP_WALL_MS = (1.8, 2.5)
"""The study's wall time per 1 ms step [ms] (low, high)."""
STUDY_HOST = "Intel i7 workstation"
"""The machine the study timed TP on."""
