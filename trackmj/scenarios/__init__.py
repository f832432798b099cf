"""Operating conditions: the study's W1-W5 and NL1 as TOML files (``experiments/``),
loaded into frozen dataclasses by the one validator.

* :mod:`.schema`: the scenario file's tables and :func:`~trackmj.scenarios.schema.load_scenario`.
"""
