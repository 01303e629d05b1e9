"""Rigorous error bounds: the error ellipsoid with rounding, its amortised read, the Kalman
sample's factored step, the paper's envelopes."""
