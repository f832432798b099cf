"""Closed-loop simulation: one run of one operating condition, assembled from registered
blocks and stepped by the one loop.

* :mod:`.setup`: everything a run is made of, loaded and validated before anything is built;
* :mod:`.entries`, :mod:`.controllers`, :mod:`.registry`: the registries (controllers and
  estimators; mechanics, elements, architectures, the reference architecture);
* :mod:`.architectures`, :mod:`.mechanics`, :mod:`.loop_plants`, :mod:`.control_plant`: the
  assembly of a run's plant and the controller's reduced model;
* :mod:`.loop`: the one closed loop, controller -> valves -> plant -> sensors -> estimator
  -> observers; :mod:`.observers`: the recorder, the physics guard, progress;
* :mod:`.run`: :func:`~trackmj.sim.run.simulate`; :mod:`.reduced`: the loop on the
  controller's own model; :mod:`.drive`: the bare track with its passive tensioner;
* :mod:`.w3_hitch`: W3's hitch loads calibrated per machine against the idler load (hold-mode
  runs a W3 run needs before it starts; committed for the shipped machines, else cached).
"""
