"""Closed-loop simulation: the one step loop, the block registries and the run assembly."""
