"""Every policy type RoboView evaluates, and the wire formats of served policies."""
