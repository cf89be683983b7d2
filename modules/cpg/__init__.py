"""The multi-layered multi-pattern CPG of thesis chapter 4, bus-free: circuits as data, the network, patterns."""

from .circuit import Circuit, apply_overrides, load_circuit, validate_circuit
from .network import CPGNetwork

__all__ = ["CPGNetwork", "Circuit", "apply_overrides", "load_circuit", "validate_circuit"]
