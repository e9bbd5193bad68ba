"""The world a mission flies over: ground-truth terrains and their families, the downward
camera and its noise, and the random streams every mission draws from."""

# Every terrain kind is registered wherever the package is used: the built-in kinds register
# themselves on import (terrain's, then the realistic families', which build on terrain).
from . import families, terrain  # noqa: F401
