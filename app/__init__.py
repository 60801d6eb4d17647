"""The command line, configuration and session assembly."""
