"""The sub-commands of ``footnav``, one module each."""
