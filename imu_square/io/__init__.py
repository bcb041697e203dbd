"""Recordings and their file formats: the :class:`~.recording.Recording` object,
MCAP (:mod:`.mcap`, with the CDR sample batches of :mod:`.cdr`) and CSV import
(:mod:`.csv`). One module per format, its reader and writer side by side."""
