"""Kinematics of the Hexa (6-RUS) and the 3UPS+RPU."""
