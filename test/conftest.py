"""Test-session setup shared by the core and ROS tests."""

from switchobs_core.threads import single_threaded_blas

# One process designs gains (Clarabel) and then runs observers: keep BLAS single-threaded
# (small matrices; see switchobs_core.threads).
single_threaded_blas()
