"""A gas-charged tensioning cylinder as a co-simulation FMU, written in Python (pythonfmu).

Build it:   pythonfmu build -f GasSpring.py      (writes GasSpring.fmu here)
Use it:     trackmj drive --tensioner gas_spring.toml --duration 5

Port (trackmj's signs, SI): inputs stroke_m [m] (outward +) and velocity_m_s [m/s]; output
force_N [N] on the idler carrier (> 0 pushes it outward):

    F = A * p0 * (V0 / V)^n - A * p_atm - c * v,   V = V0 + A * (s - s_ref)

an ideal gas on a piston of area A, polytropic exponent n, charged to p0 (absolute) at
stroke s_ref, with a viscous seal and orifice term c.
"""

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

from trackmj.fmi.export import hold_module_dict

hold_module_dict(globals())   # works around a reference-count bug of pythonfmu 0.7's binary

PARAMETERS = {                 # name: (value, description)
    "area_m2": (3.2e-3, "gas piston area A [m2]"),
    "p0_Pa": (4.2e6, "gas pressure at s_ref, absolute [Pa]"),
    "V0_m3": (6.0e-4, "gas volume at s_ref [m3]"),
    "s_ref_m": (0.05, "stroke at which the gas holds V0 [m]"),
    "n": (1.3, "polytropic exponent [-]"),
    "c_N_s_m": (2.0e4, "damping of seal and orifice [N s/m]"),
    "p_atm_Pa": (1.013e5, "ambient pressure on the piston's other side [Pa]"),
}


class GasSpring(Fmi2Slave):
    author = "trackmj example"
    description = "gas-charged tensioning cylinder, polytropic gas and linear damping"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.stroke_m = 0.05
        self.velocity_m_s = 0.0
        self.register_variable(Real("stroke_m", causality=Fmi2Causality.input,
                                    description="stroke, outward + [m]"))
        self.register_variable(Real("velocity_m_s", causality=Fmi2Causality.input,
                                    description="stroke velocity over the step [m/s]"))
        for name, (value, text) in PARAMETERS.items():
            setattr(self, name, value)
            self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                        variability=Fmi2Variability.tunable,
                                        description=text))
        self.force_N = self.force()
        self.register_variable(Real("force_N", causality=Fmi2Causality.output,
                                    description="force on the idler carrier, outward + [N]"))

    def force(self) -> float:
        """The law of the module docstring at the inputs [N]."""
        volume = self.V0_m3 + self.area_m2 * (self.stroke_m - self.s_ref_m)
        gas = self.area_m2 * self.p0_Pa * (self.V0_m3 / volume) ** self.n
        return gas - self.area_m2 * self.p_atm_Pa - self.c_N_s_m * self.velocity_m_s

    def exit_initialization_mode(self):
        self.force_N = self.force()

    def do_step(self, current_time, step_size):
        self.force_N = self.force()
        return True
