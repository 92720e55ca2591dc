"""What the scenario generator can vary: plain constants, importable without numpy or numba
(the `conag` command line builds its argument parser from them on every start)."""

# The families of generator version 1: a suite (`suite_plan`) and an unset family draw from these,
# so the files they made before the later families came are made again, byte for byte.
SUITE_FAMILIES = ("wall", "ring", "nested_rings", "pocket", "letter", "polyomino", "multi")
# Later families, asked for by name (or in a suite that lists them): solid blocks and compact
# blobs up to 10 x 10, one-cell square spirals, one-cell winding corridors, solid-and-hollow shapes.
SOLID_FAMILIES = ("block", "spiral", "corridor", "solid_hollow")
FAMILIES = SUITE_FAMILIES + SOLID_FAMILIES
SOURCES = ("pile", "scattered", "sources")   # one compact pile, single bricks, several piles far apart
MIN_SIZE, MAX_SIZE = 15, 120                 # cells a side
# A team of up to MAX_TEAM starts side by side, as the paper's agents do; a larger crowd
# (up to MAX_AGENTS, the most a world's status message lists) is spread over the floor.
MAX_TEAM = 12
MAX_AGENTS = 1024
SIZE_BANDS = ((15, 30), (31, 60), (61, 120))
