from lensaudit.console import run

run()
