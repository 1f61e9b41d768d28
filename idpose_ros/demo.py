"""`./run demo`: the main job on the embedded default. Placeholder until the pipeline exists."""
import sys


def main() -> int:
    print("idpose_ros demo: the estimation pipeline is not built yet; nothing was estimated.", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
