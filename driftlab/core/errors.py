"""DriftLab's exceptions: each subclasses the built-in a caller would expect."""


class ConfigError(ValueError):
    """A configuration value is missing, unknown or out of its allowed range (the message names it)."""


class NoEquilibriumError(ValueError):
    """No drift equilibrium of the requested kind exists for the given radius and sideslip."""
