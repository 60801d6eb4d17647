"""The OpenShoe / MIMU / Oblu protocol: the framer, the host commands, one codec per output mode."""

from typing import TYPE_CHECKING

from footnav.pipeline._lazy import lazy_exports

if TYPE_CHECKING:
    from .commands import Command as Command
    from .commands import CommandParser as CommandParser
    from .commands import Commands2014 as Commands2014
    from .commands import Commands2015 as Commands2015
    from .commands import CommandSet as CommandSet
    from .commands import commands_for as commands_for
    from .extensions import BaroBatch as BaroBatch
    from .extensions import TofBatch as TofBatch
    from .framer import DataPacket as DataPacket
    from .framer import DeviceAck as DeviceAck
    from .framer import Frame as Frame
    from .framer import Framer as Framer
    from .ins_states import InsLayout as InsLayout
    from .ins_states import InsStateBatch as InsStateBatch
    from .raw_imu import RawImuBatch as RawImuBatch
    from .raw_imu import RawImuLayout as RawImuLayout
    from .stepwise import StepBatch as StepBatch
    from .stepwise import StepwiseTracker as StepwiseTracker
else:  # type checkers read the imports above; at run time the same names are lazy attributes
    __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
