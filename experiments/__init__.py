"""trackmj's built-in scenarios and scripted studies.

Every ``*.toml`` here named like a scenario and holding a ``[scenario]`` table is a built-in
scenario, loaded by its name (:func:`trackmj.scenarios.load.builtin_names`): the study's
W1-W5 and NL1; dropping a file in adds one. ``controllers.toml`` is a sweep spec (a
``[sweep]`` table), ``calibrate_w3.py`` a script.
"""
