"""The ``mrm`` command line: the same core as the nodes, run offline."""
