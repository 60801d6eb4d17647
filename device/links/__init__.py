"""Byte links to a unit: USB-CDC serial, BLE, and the reconnecting link that survives faults."""
