"""psychopy-thermode: PsychoPy plugin for thermode thermal displays (`ThermodeDevice`)."""

from .device import ThermodeDevice

__all__ = ["ThermodeDevice"]
__version__ = "0.1.0"
