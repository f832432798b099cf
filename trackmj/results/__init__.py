"""What a run leaves and how it is read.

* :mod:`.store`: the timeseries table and result directories written whole or not at all;
* :mod:`.measured`: measured logs and input traces (CSV, Parquet);
* :mod:`.signals`: the metrics of one signal (RMSE, overshoot, settling, low-pass, PSD, ...);
* :mod:`.metric_windows`: the windows, bands and settings a run's metrics are measured on;
* :mod:`.energy_terms`: a run's energy terms read from its ``energy_J`` table;
* :mod:`.acceptance`: the tensioner's acceptance checks on the trailing mean of F_ten;
* :mod:`.metrics`: a run's metric set and the registry of every metric;
* :mod:`.comparison`: how far a run is from the reference architecture's run or a measured log;
* :mod:`.columns`: a results column's unit, display unit, words and axis label;
* :mod:`.seed_stats`: mean ± std over seeds of the finite values;
* :mod:`.figure_style`: the look every figure shares (colours, line styles, legends, PNG);
* :mod:`.figure_panels`: the tension panel, force band, event windows and zooms of figures;
* :mod:`.figure_energy`: a run's energy as a waterfall of bars;
* :mod:`.figure_run`: the figure of one run;
* :mod:`.figure_compare`: the figures that compare runs (overlay, spectra, variants, fit);
* :mod:`.figure_sweep`: the figures of a sweep's results table;
* :mod:`.figure_calibration`: the figure of a calibration (estimates, fits, residuals);
* :mod:`.figure_drive`: the figure of a bare-track drive (forces, strands, derailment checks);
* :mod:`.playback`: the Rerun recording of a run.
"""
