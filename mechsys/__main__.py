from mechsys.cli import main

main()
