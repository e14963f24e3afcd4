"""Studies built on the engine: the Monte Carlo study (simulate), the UWB pipeline, and the
sample data generators."""
