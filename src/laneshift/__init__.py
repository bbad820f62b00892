"""laneshift: the import root; the shared contract lives on this floor.

Room: the contract (shared by every process). May import: other contract modules only, never a
component, deploy or a tool."""


def __getattr__(name: str) -> str:
    """``laneshift.__version__``: the installed distribution's version (importlib.metadata), read on
    first use so that importing laneshift stays free of importlib.metadata's own imports; ``0+unknown``
    in a source tree that is not installed."""
    if name != "__version__":
        raise AttributeError(f"module 'laneshift' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("laneshift")
    except PackageNotFoundError:
        value = "0+unknown"
    globals()["__version__"] = value
    return value
