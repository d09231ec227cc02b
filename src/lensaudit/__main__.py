from lensaudit.cli import main

main()
