"""DriftLab's exceptions: each subclasses the built-in a caller would expect."""


class ConfigError(ValueError):
    """A configuration value is missing, unknown or out of its allowed range (the message names it; ``field``,
    when given, is the key the message is about, for the API's error list)."""

    def __init__(self, message: str, *, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class OutsideDriftWindowError(ConfigError):
    """The scenario's sideslip is outside the sideslips at which a job of this car can drift a circle (``window``:
    [low, high] rad, None where it drifts at none)."""

    def __init__(self, message: str, *, field: str | None = None,
                 window: tuple[float, float] | None = None) -> None:
        super().__init__(message, field=field)
        self.window = window


class NoEquilibriumError(ValueError):
    """No drift equilibrium of the requested kind exists for the given radius and sideslip."""
