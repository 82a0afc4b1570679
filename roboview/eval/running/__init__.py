"""Running episodes: rollouts, backends (local, Ray, shards), the policy server, the results store,
provenance, videos, Rerun recordings and the isolation certificate."""
