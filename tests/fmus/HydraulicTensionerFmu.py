"""trackmj's built-in hydraulic tensioner as a co-simulation FMU (pythonfmu): the round-trip
test's FMU. Inputs: end-of-step stroke [m], the step's velocity [m/s], valve mode
(+1/0/−1); outputs: the cylinder force at the communication point [N] (at the end-of-step
pressures), the cylinder force over the step just taken [N] (at the pressures' mean over
it, what the built-in plugin hands the track), mean head, rod and supply pressure [Pa gauge].
Each doStep is one backward-Euler step of the plugin at the given velocity (its weak
coupling's completion: Newton from the last pressures); its state can be saved and
restored (a copy of the plugin's state array and solenoids; its ledger views are not
re-pointed: the FMU outputs no energies)."""

import copy

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String

from trackmj.fmi.export import hold_module_dict

hold_module_dict(globals())   # pythonfmu's findClass releases this dict once too often


class HydraulicTensionerFmu(Fmi2Slave):
    author = "trackmj tests"
    description = "trackmj.hydraulics.HydraulicTensioner as an FMU"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.stroke_m = 0.05
        self.velocity_m_s = 0.0
        self.valve_mode = 0
        self.force_N = 0.0
        self.step_force_N = 0.0
        self.p_head_Pa = 0.0
        self.p_rod_Pa = 0.0
        self.p_supply_Pa = 0.0
        self.head_pressure_Pa = 2.0e6
        self.supply_model = ""
        self.ht = None
        self._mode = None
        for name in ("stroke_m", "velocity_m_s"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        self.register_variable(Integer("valve_mode", causality=Fmi2Causality.input,
                                       variability=Fmi2Variability.discrete))
        for name in ("force_N", "step_force_N", "p_head_Pa", "p_rod_Pa", "p_supply_Pa"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))
        self.register_variable(Real("head_pressure_Pa", causality=Fmi2Causality.parameter,
                                    variability=Fmi2Variability.tunable))
        self.register_variable(String("supply_model", causality=Fmi2Causality.parameter,
                                      variability=Fmi2Variability.tunable))

    def exit_initialization_mode(self):
        from trackmj.hydraulics import HydraulicTensioner

        self.ht = HydraulicTensioner(stroke_m=self.stroke_m,
                                     head_pressure_Pa=self.head_pressure_Pa,
                                     supply_model=self.supply_model or None, coupling="weak")
        self._set_mode()
        _, p_hl, p_hr, p_b, p_s = self.ht.pressures
        ht = self.ht
        self.force_N = self.step_force_N = ht.Ah * (p_hl + p_hr) - 2.0 * ht.Ar * p_b
        self.p_head_Pa, self.p_rod_Pa, self.p_supply_Pa = 0.5 * (p_hl + p_hr), p_b, p_s

    def _set_mode(self):
        if self.valve_mode != self._mode:
            self.ht.set_mode(int(self.valve_mode))
            self._mode = self.valve_mode

    def do_step(self, current_time, step_size):
        ht = self.ht
        self._set_mode()
        ht.force_law(current_time, ht.s, ht.v)
        ht.complete_step(current_time + step_size, self.stroke_m, self.velocity_m_s)
        rec = ht.record
        self.step_force_N = rec.force_N
        self.force_N = (ht.Ah * (rec.p_head_L_Pa + rec.p_head_R_Pa) - 2.0 * ht.Ar * rec.p_rod_L_Pa
                        - rec.friction_N + rec.endstop_N)
        row = ht.log()
        self.p_head_Pa = row.p_head_Pa
        self.p_rod_Pa, self.p_supply_Pa = row.p_rod_Pa, row.p_supply_Pa
        return True

    def _get_fmu_state(self):
        ht = copy.copy(self.ht)
        ht._state = self.ht._state.copy()
        ht.main, ht.vl, ht.vr = copy.deepcopy((self.ht.main, self.ht.vl, self.ht.vr))
        return (ht, self._mode, self.force_N, self.step_force_N, self.p_head_Pa,
                self.p_rod_Pa, self.p_supply_Pa)

    def _set_fmu_state(self, state):
        (saved, self._mode, self.force_N, self.step_force_N, self.p_head_Pa, self.p_rod_Pa,
         self.p_supply_Pa) = state
        ht = copy.copy(saved)
        ht._state = saved._state.copy()
        ht.main, ht.vl, ht.vr = copy.deepcopy((saved.main, saved.vl, saved.vr))
        self.ht = ht
