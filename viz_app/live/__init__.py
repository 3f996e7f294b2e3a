"""Live radar feeds: ``radarviz replay`` sends a capture to a UDP address at its pace,
``radarviz live`` tracks a feed as it arrives (``run``, ``session``)."""
