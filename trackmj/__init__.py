"""trackmj: electro-hydraulic track tensioning simulator.

This top-level module stays import-light (no mujoco import) because the pure
subpackages ``trackmj.hydraulics`` and ``trackmj.control`` live under it and must be
importable without MuJoCo.
"""

__version__ = "0.1.0"
