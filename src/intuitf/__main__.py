from intuitf.cli.app import main

main()
