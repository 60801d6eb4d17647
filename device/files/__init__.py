"""Files: footnav's captures, and the recordings of other tools."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .capture import CaptureInfo as CaptureInfo
    from .capture import CaptureMessage as CaptureMessage
    from .capture import CaptureSummary as CaptureSummary
    from .capture import CaptureWriter as CaptureWriter
    from .capture import UnitHeader as UnitHeader
    from .capture import iter_capture as iter_capture
    from .capture import read_capture_info as read_capture_info
    from .capture import summarize_capture as summarize_capture
    from .recordings import LOADERS as LOADERS
    from .recordings import CsvMapping as CsvMapping
    from .recordings import Recording as Recording
    from .recordings import detect_format as detect_format
    from .recordings import load_generic_csv as load_generic_csv
    from .recordings import load_recording as load_recording
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
