from mechsys.cli import entry

entry()
