"""`python -m mechsys`: the mechsys command line."""
from mechsys.cli import entry

entry()
