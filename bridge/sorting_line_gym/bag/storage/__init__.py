"""Storage, as rosbag2's storage layer: bags on disk and nothing of ROS. Reading (:mod:`.reader`)
and writing (:mod:`.writer`, crash-safe, split and compressed; :mod:`.metadata`, metadata.yaml)
bags, copying one into another (:mod:`.rewrite`), recovering a bag whose recorder died
(:mod:`.recovery`), what a recording missed (:mod:`.losses`), bags of other recorders
(:mod:`.foreign`), and the message types with their decoding (:mod:`.schema`). Uses only
:mod:`..format` below it.
"""
