"""Rauch–Tung–Striebel smoothing: of a whole recording, and step by step while a session runs."""
