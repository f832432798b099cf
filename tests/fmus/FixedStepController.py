"""A controller of a fixed sample time (20 ms) as a co-simulation FMU (pythonfmu), standing
in for an export that declares it can handle a variable communication step (pythonfmu
declares it) yet discards any other: u = stroke [m], held over its period."""

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Real

from trackmj.fmi.export import hold_module_dict

hold_module_dict(globals())   # pythonfmu's findClass releases this dict once too often

SAMPLE_TIME_S = 0.02


class FixedStepController(Fmi2Slave):
    author = "trackmj tests"
    description = "a controller of a fixed 20 ms sample time"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=10.0,
                                           step_size=SAMPLE_TIME_S)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.stroke = self.u = 0.0
        self.register_variable(Real("stroke", causality=Fmi2Causality.input))
        self.register_variable(Real("u", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        if abs(step_size - SAMPLE_TIME_S) > 1e-12:
            return False   # fmi2Discard
        self.u = self.stroke
        return True
