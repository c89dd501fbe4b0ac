import sys
from pathlib import Path

# Generated test meshes live next to the tests.
sys.path.insert(0, str(Path(__file__).parent))
