"""The version of flockkit (one place: the package, its provenance records and exports read it)."""

__version__ = "0.1.0"
