import sys

try:
    from .cli import main
except KeyboardInterrupt:  # Ctrl-C while Python imports crankfmu: nothing started yet
    print("error: interrupted (Ctrl-C)", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
