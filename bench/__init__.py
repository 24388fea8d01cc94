"""vasim benchmarks: `make bench` (= `python -m bench`) runs every module listed in
``bench.__main__.BENCHES`` and prints figures and ratios (never asserts wall-clock times)."""
