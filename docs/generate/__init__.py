"""What the documentation build generates from the code (called by docs/hooks.py): the reference
pages' tables, so that a reference that disagrees with the code cannot be built."""
