"""What the scenario generator can vary: plain constants, importable without numpy or numba
(the `conag` command line builds its argument parser from them on every start)."""

FAMILIES = ("wall", "ring", "nested_rings", "pocket", "letter", "polyomino", "multi")
SOURCES = ("pile", "scattered", "sources")   # one compact pile, single bricks, several piles far apart
MIN_SIZE, MAX_SIZE = 15, 120                 # cells a side
MAX_AGENTS = 12
SIZE_BANDS = ((15, 30), (31, 60), (61, 120))
