"""A proportional tension controller as a co-simulation FMU (pythonfmu), standing in for a
Simulink-exported controller in the tests: u = clip(kp·(F_ref − F), −1, 1) with
F = p_head·A_head − p_rod·A_rod, held over its period."""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

from trackmj.fmi.export import hold_module_dict

hold_module_dict(globals())   # pythonfmu's findClass releases this dict once too often


class TensionController(Fmi2Slave):
    author = "trackmj tests"
    description = "proportional tension controller"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.p_head = self.p_rod = self.F_ref = self.u = 0.0
        self.area_head = 4.0e-3
        self.area_rod = 2.0e-3
        self.kp = 1.0e-3
        for name in ("p_head", "p_rod", "F_ref"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        self.register_variable(Real("u", causality=Fmi2Causality.output))
        for name in ("area_head", "area_rod", "kp"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable))

    def do_step(self, current_time, step_size):
        force = self.p_head * self.area_head - self.p_rod * self.area_rod
        self.u = max(-1.0, min(1.0, self.kp * (self.F_ref - force)))
        return True
