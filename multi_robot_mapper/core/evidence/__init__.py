"""The evidence model of every place match (issue 46): a loop closure, a join of two pieces
of a robot's map, a link between robots. Each decision places one map's walls (a *patch*) on
another map; :mod:`.placement` measures the wall the placement explains that its best rival
placement anywhere on that map does not, and the walls it puts in free space; :mod:`.model`
turns these into the probability that the decision is right, with one fitted model for every
kind of decision. :mod:`.correlation` is the map correlation both rest on.
"""
