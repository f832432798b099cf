"""Studies made of many runs, and the procedures that derive a machine's files.

* :mod:`.campaign`: runs into one directory, each known by its identity, resumable;
* :mod:`.executor`, :mod:`.worker`: the Dask executor and its warmed workers;
* :mod:`.compare`, :mod:`.report`, :mod:`.sweep`: ``trackmj compare``, ``report``, ``sweep``;
* :mod:`.calibrate`: ``trackmj calibrate``, parameter keys fitted to measured logs;
* :mod:`.w3_hitch`: W3's hitch load calibrated against the idler load;
* :mod:`.identify`: the equivalent idler identified on the MuJoCo track.
"""
