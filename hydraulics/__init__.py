"""Hydraulic tensioning circuit (pure numpy/scipy; never imports mujoco)."""
