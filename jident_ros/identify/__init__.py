"""Identification over time: per-drive trend tracking of the window estimates (J1, backlash width)."""
