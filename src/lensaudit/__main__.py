from lensaudit.cli import run

run()
