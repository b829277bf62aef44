"""Module 3, feedrate planning (eqs. 23-26): the feed-limit curve, quintic Bernstein feed
profiles, the planner and its checks, and the time-optimal bound. May import the base layer and
controller.geometry.
"""
