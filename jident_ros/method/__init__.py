"""Signal-processing stages of the J1 identification method (paper sections 3-4)."""
