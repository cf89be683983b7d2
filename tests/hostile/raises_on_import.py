"""A user module whose import fails (for tests/hostile/impl_raises.yaml)."""

raise RuntimeError("boom on import")
