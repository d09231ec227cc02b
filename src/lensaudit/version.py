"""lensaudit's version, in a module of its own: whatever needs it imports this,
never the package, whose functions import the pipeline."""

__version__ = "0.1.0"
