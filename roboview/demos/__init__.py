"""Scripted-expert demos recorded into LeRobot datasets."""
