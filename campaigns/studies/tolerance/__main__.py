"""``python -m campaigns.studies.tolerance``: planning study (c) (:mod:`campaigns.studies.tolerance`)."""

from campaigns.studies.tolerance import main

raise SystemExit(main())
