"""trackmj model files: lf1352.xml (generated) and its parameter files."""
