"""Files: footnav's captures, and the recordings of other tools."""
