"""The dual-IMU board: the shared rigid-body model, footnav's board filter, the Chen et al. (2022) filter, the
lever-arm check."""
