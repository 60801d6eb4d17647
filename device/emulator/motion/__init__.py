"""The emulated walker: courses, floors, and the motion of one instrumented foot."""
