"""The verbs: one module per console script (`roboview-<verb>`), each parsing flags and calling the library."""
