from nurbscnc.cli.main import main

main()
