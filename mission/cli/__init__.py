"""The `groundfx` command line: `main` builds the parser; one module per subcommand family."""

import os

# numpy's OpenBLAS runs a thread per core on matrices as small as ours (a diagnosis's least
# squares: 17.5 s of CPU against 13 s with one thread on a quiet 2-core machine, 22 against
# 14 beside other work, and no sooner done): its spinning threads only take a core from
# whatever else runs.
# One thread unless the user says otherwise; set before numpy's first import.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
