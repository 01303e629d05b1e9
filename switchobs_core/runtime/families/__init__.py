"""The gain families, one module each (the registry is :mod:`switchobs_core.families`)."""
