"""The emulated unit served to hosts: on a pseudo-terminal, as a BLE peripheral, with wire faults."""
