"""Run folders in other tools' formats (``auvmpc export``)."""

from auvmpc.export.rosbag2 import TOPICS, export_rosbag2

__all__ = ["TOPICS", "export_rosbag2"]
