"""Measurements behind `bench`, `bench --error` and `compare`: rows and
reports as plain dicts; the command line (cli/) prints and plots them."""
