"""The bag format, the leaf every other part of `sorting_line_gym.bag` builds on: the names of a
sorting line bag's topics and types (:mod:`.topics`), the keys of its ``custom_data`` and the
line's description (:mod:`.description`), how a bag is written and which node options a bag's
line takes from flags (:mod:`.options`), and the errors of bad bags and failed writes
(:mod:`.errors`). Nothing here reads, writes or talks to ROS, and nothing here imports another
part of the bag tools.
"""
