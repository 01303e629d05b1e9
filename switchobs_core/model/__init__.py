"""The model: the LTI system and its channels, schedules and cycles, noise, built-in scenarios,
measurements, decomposition, detectability."""
