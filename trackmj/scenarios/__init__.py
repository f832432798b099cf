"""Operating conditions: the study's W1-W5 and NL1 as TOML files (``experiments/``).

* :mod:`.schema`: the scenario file's tables, read by the one validator.
* :mod:`.resolve`: relative values made absolute for a machine.
* :mod:`.inputs`: the ``from_file`` input signals.
* :mod:`.resolved`: the resolved :class:`~trackmj.scenarios.resolved.Scenario` and its
  signals, road profile and metric windows.
* :mod:`.load`: the built-in scenarios and
  :func:`~trackmj.scenarios.load.load_scenario`.
* :mod:`.events`: a scenario's events and moving them into a short run.
"""
