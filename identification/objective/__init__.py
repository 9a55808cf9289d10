"""The identification problem: one record (or several, jointly) and a
contact model as a function of the design variables, its objectives
(pointwise, likelihood, statistics), the declared noise, the Jacobian and
the intervals of a result."""
