"""Planners behind one seam (`seam.Planner`): what a planner is given each tick and what it returns.

`registry.make` builds the planner a scenario names; the in-process engine and the agent process both plan
through it, so a planner added here runs in `reconswarm sim`, the launch and `reconswarm sweep` alike.
"""
