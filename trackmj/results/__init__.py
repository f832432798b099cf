"""What a run leaves and how it is read.

* :mod:`.store`: the timeseries table and result directories written whole or not at all;
* :mod:`.metrics`: the performance metrics of a run;
* :mod:`.measured`: measured logs and input traces (CSV, Parquet);
* :mod:`.figures`: PNG figures of runs and comparisons;
* :mod:`.playback`: the Rerun recording of a run.
"""
