"""The mission core (team rules, reset and step, the lock-step driver) and what is derived
from a mission state: feature planes and rendering."""
