"""Benchmark of the reconstruction: fast path against the reference path (see README.md).

    python benchmarks/bench.py [--quick] [--json] [--device gpu] [--cache DIR] [--no-reference]

The same as ``ssdpc bench``; the code lives in ``napari_ssdpc.validation.bench`` so that an installed
package can run it too.
"""

import sys

from napari_ssdpc.cli.main import main

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
