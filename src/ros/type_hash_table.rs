//! The RIHS01 hash of every interface the node's endpoints use, as rosidl computed them.
//! Generated: `.venv/bin/python tests/python/type_hashes.py --write`. Do not edit;
//! tests/python/test_type_hash.py fails when this differs from rosidl's.

/// (ROS type name, RIHS01 hash), sorted by name.
pub const TYPE_HASHES: &[(&str, &str)] = &[
    ("diagnostic_msgs/msg/DiagnosticArray", "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e"),
    ("rcl_interfaces/msg/Log", "RIHS01_e28ce254ca8abc06abf92773b74602cdbf116ed34fbaf294fb9f81da9f318eac"),
    ("rcl_interfaces/msg/ParameterEvent", "RIHS01_043e627780fcad87a22d225bc2a037361dba713fca6a6b9f4b869a5aa0393204"),
    ("rcl_interfaces/srv/DescribeParameters_Request", "RIHS01_05dd1c2bc87dec2627105c8070d6f9725c781a4f2ab852975bf105462b82b644"),
    ("rcl_interfaces/srv/DescribeParameters_Response", "RIHS01_ad6747319613c6131589e062e095b469a46cc764f7d0f12a001a49e6cd893995"),
    ("rcl_interfaces/srv/GetParameterTypes_Request", "RIHS01_87d7ec5ef545d4daa289d500025d31fb2437bc8b8365ca367161c4dac4be33fd"),
    ("rcl_interfaces/srv/GetParameterTypes_Response", "RIHS01_ac1335dce67c478e669434f6ac2fbff34fcd529580f272d3006785ba8b54e47f"),
    ("rcl_interfaces/srv/GetParameters_Request", "RIHS01_135a9e1c3d7cebef792f6687d7ddf99949b21a0bd9a320d863a9110a3f5cf4d6"),
    ("rcl_interfaces/srv/GetParameters_Response", "RIHS01_9fa773b46e39cc5d02db6224d8fd520bb9caeeffc2b27c96c1e59431baba9f2a"),
    ("rcl_interfaces/srv/ListParameters_Request", "RIHS01_a1b0b5d6b967a5b8ac5bc8563c3ea678f349e312a6a4967227c5a96bc5ce38df"),
    ("rcl_interfaces/srv/ListParameters_Response", "RIHS01_31b937b82de3612426be79f231e386259f97e8dc843e3f2845288b4bfa296bdd"),
    ("rcl_interfaces/srv/SetParameters_Request", "RIHS01_130d46386b7e84ea9ecf60608a4d83cbe5e5cb7c6cc5b712b7a4e3a6c254e932"),
    ("rcl_interfaces/srv/SetParameters_Response", "RIHS01_7a0e8140a0b8d98308fa81a5403a766e610af29a239caf54b7553227906fc266"),
    ("rcl_interfaces/srv/SetParametersAtomically_Request", "RIHS01_db0bd950ed5ed867a0e90b225e44dea382d762c0762ff3e0ee842190042a59e5"),
    ("rcl_interfaces/srv/SetParametersAtomically_Response", "RIHS01_31b1a38c5b0b9d893ee24da45f69638f4561c78461d82d52750f429b534502b8"),
    ("rmw_dds_common/msg/ParticipantEntitiesInfo", "RIHS01_91a0593bacdcc50ea9bdcf849a938b128412cc1ea821245c663bcd26f83c295e"),
    ("rosgraph_msgs/msg/Clock", "RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564"),
    ("sorting_line_interfaces/msg/BeltOccupancy", "RIHS01_f3f783fc5c6cda0a7813a3a34ff5a512d77a4dc0262a183fcb7365ff7a254f82"),
    ("sorting_line_interfaces/msg/EvolutionEvent", "RIHS01_566a8bf49b00dae860d4990d4501392ff2c153e901f167b548d6883f040a1611"),
    ("sorting_line_interfaces/msg/LineCommands", "RIHS01_16844149071f7ef1eded2e1115510c13fa3f9975bde1cac3c61f54d86f8f9801"),
    ("sorting_line_interfaces/msg/LineState", "RIHS01_f960d663f175fb957d5d0f04d630e30dcba23913e91dca00dcf85cfbf1da2a6c"),
    ("sorting_line_interfaces/msg/LineStates", "RIHS01_817712176a3d3dbe9e6f90339519fc99bfd93071405c0d7152c588a012849066"),
    ("sorting_line_interfaces/msg/MaterialInput", "RIHS01_9ba651f841870e9bd2cfd0424d944e685c2fcae059393373f5b08056333719ce"),
    ("sorting_line_interfaces/msg/MaterialRatio", "RIHS01_9f4d135853fe649f249ffa27690e3572f1463590178368e991bde14381c83155"),
    ("sorting_line_interfaces/msg/ResetEvent", "RIHS01_323fd029d5dcf5020a1184f43ac63b05f84326050bffc5d8de84361c74de537c"),
    ("sorting_line_interfaces/msg/SortModeCommand", "RIHS01_72318357a08ec6e9de74050f45e36f75f8404f177d4c16a628032f232caa705f"),
    ("sorting_line_interfaces/msg/SpeedCommand", "RIHS01_768c9f5fae3892afd877e829d5a602398b35a9274f0379211962fae37196ddab"),
    ("sorting_line_interfaces/srv/ResetLine_Request", "RIHS01_6f8910f0b93de51d20d7d028ab5ad02646c4a555f265b5683fe75ecd1d756521"),
    ("sorting_line_interfaces/srv/ResetLine_Response", "RIHS01_5fa2eb4f928509bef99b6c195f11776fcf65d647ddb76b35d724c1be741d9fbd"),
    ("sorting_line_interfaces/srv/ResetLines_Request", "RIHS01_fb0ee281e27596cb6b06af20f2ea631fb9eefa5a468013afe0ac0c4451703589"),
    ("sorting_line_interfaces/srv/ResetLines_Response", "RIHS01_25363ec87a91d82789d2aba08f22f38e01ca24887d4c8fe91579ff9ae52519c7"),
];
