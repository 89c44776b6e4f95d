"""Per-episode recording in rosbag2 layout (metadata.yaml + MCAP, ROS 2 CDR, ros2msg schemas).

`episode_recorder.EpisodeRecorder` writes the bags, `bag_reader` reads them without ROS,
`player.play` republishes them (rclpy), `offline.rebuild_from_bags` feeds them to the learner.
Only `player` and `EpisodeRecorder.record_message` need rclpy.
"""
