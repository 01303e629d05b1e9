"""Design time: LMI gain synthesis and eta selection, the periodic Kalman design (doubling), schedule planning."""
