"""The version of spikectl (``spikectl.__version__``), in a module of the bottom layer so
that whatever records it (a checkpoint's header) imports down, never up."""

__version__ = "0.1.0"
