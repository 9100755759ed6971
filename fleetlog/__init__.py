"""fleetlog: the MOOS logger and player rebuilt on Eclipse Zenoh for fleets of vehicles."""

__version__ = "0.1.0"
__all__ = ["__version__"]
