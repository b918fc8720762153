"""The bench live: streaming estimators and the Tango device."""

__all__: list[str] = []
