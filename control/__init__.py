"""Control layer: valve logic, estimators, NMPC/LMPC/PID (never imports mujoco)."""
