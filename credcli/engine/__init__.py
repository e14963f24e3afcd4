"""The engine: metrics, the location test, the scale test, dependence estimates and the
decision rules. Pure array functions and frozen results; nothing here knows about files,
flags or JSON keys."""
