"""Bytes <-> packets and the units themselves: protocol codecs, transports, discovery, the emulator."""
