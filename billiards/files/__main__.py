"""``python -m billiards.files verify RUN_DIR...`` (:func:`billiards.files.summaries.main`)."""

from .summaries import main

if __name__ == "__main__":
    raise SystemExit(main())
