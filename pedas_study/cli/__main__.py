"""``python -m pedas_study.cli``: the same as the `pedas-study` command."""
import sys

from pedas_study.cli import main

sys.exit(main())
