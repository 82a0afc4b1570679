"""The frozen benchmark: render instances, the fairness gate, the benchmark folder, conformance."""
