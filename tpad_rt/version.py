"""tpad-rt's version (re-exported as ``tpad_rt.__version__``)."""

__version__ = "0.1.0"
