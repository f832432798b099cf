"""Studies made of many runs, and the procedures that derive a machine's files.

* :mod:`.campaign`: runs into one directory, resumable, one row per run;
* :mod:`.identity`: what a run is known by (its identity and the keys hashed from it);
* :mod:`.executor`, :mod:`.worker`: the Dask executor and its warmed workers;
* :mod:`.compare`, :mod:`.report`, :mod:`.sweep`: ``trackmj compare``, ``report``, ``sweep``
  (the report's parts in ``report_*`` and the study's figures in :mod:`.study_numbers`);
* :mod:`.calibrate`: ``trackmj calibrate``, parameter keys fitted to measured logs (its
  spec file in :mod:`.calibrate_spec`).
"""
