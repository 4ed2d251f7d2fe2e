from povlens.cli import run

run()
