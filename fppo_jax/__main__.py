import sys

from fppo_jax.cli import main

sys.exit(main())
