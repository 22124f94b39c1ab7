//! The `ros2msg` schema of every type the node publishes, as Foxglove (its WebSocket protocol
//! and MCAP) expects one: the type's .msg text, then each type it uses, depth first, after a line
//! of 80 `=` and `MSG: pkg/Type`, the concatenated form rosbag2 and foxglove_bridge write. The
//! line's own types come from the .msg files the interface package is built from (msg/msg), so a
//! field added there reaches the live view's decoders without a second copy; the standard types'
//! texts are Jazzy's (comments left out). Text only, no I/O.

/// The .msg text of a type the node's messages use, by its full name (`pkg/msg/Type`).
fn definition(ros_type: &str) -> Option<&'static str> {
    Some(match ros_type {
        "sorting_line_interfaces/msg/MaterialInput" => include_str!("../../msg/msg/MaterialInput.msg"),
        "sorting_line_interfaces/msg/BeltOccupancy" => include_str!("../../msg/msg/BeltOccupancy.msg"),
        "sorting_line_interfaces/msg/MaterialRatio" => include_str!("../../msg/msg/MaterialRatio.msg"),
        "sorting_line_interfaces/msg/LineState" => include_str!("../../msg/msg/LineState.msg"),
        "sorting_line_interfaces/msg/LineStates" => include_str!("../../msg/msg/LineStates.msg"),
        "sorting_line_interfaces/msg/ResetEvent" => include_str!("../../msg/msg/ResetEvent.msg"),
        "sorting_line_interfaces/msg/EvolutionEvent" => include_str!("../../msg/msg/EvolutionEvent.msg"),
        "sorting_line_interfaces/msg/SpeedCommand" => include_str!("../../msg/msg/SpeedCommand.msg"),
        "sorting_line_interfaces/msg/SortModeCommand" => include_str!("../../msg/msg/SortModeCommand.msg"),
        "sorting_line_interfaces/msg/LineCommands" => include_str!("../../msg/msg/LineCommands.msg"),
        "std_msgs/msg/Header" => "builtin_interfaces/Time stamp\nstring frame_id\n",
        "builtin_interfaces/msg/Time" => "int32 sec\nuint32 nanosec\n",
        "rosgraph_msgs/msg/Clock" => "builtin_interfaces/Time clock\n",
        "diagnostic_msgs/msg/DiagnosticArray" => "std_msgs/Header header\nDiagnosticStatus[] status\n",
        "diagnostic_msgs/msg/DiagnosticStatus" => concat!(
            "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n",
            "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n"
        ),
        "diagnostic_msgs/msg/KeyValue" => "string key\nstring value\n",
        "sorting_line_interfaces/srv/ResetLine_Request" => service_part(include_str!("../../msg/srv/ResetLine.srv"), 0),
        "sorting_line_interfaces/srv/ResetLine_Response" => {
            service_part(include_str!("../../msg/srv/ResetLine.srv"), 1)
        }
        _ => return None,
    })
}

/// The request (0) or response (1) part of a .srv text.
fn service_part(srv: &'static str, part: usize) -> &'static str {
    let (request, response) = srv.split_once("\n---\n").unwrap_or((srv, ""));
    if part == 0 {
        request
    } else {
        response
    }
}

/// Whether a .msg field type is a primitive (or a string), not a message.
fn is_primitive(base: &str) -> bool {
    matches!(
        base,
        "bool"
            | "byte"
            | "char"
            | "float32"
            | "float64"
            | "int8"
            | "uint8"
            | "int16"
            | "uint16"
            | "int32"
            | "uint32"
            | "int64"
            | "uint64"
            | "string"
            | "wstring"
    )
}

/// The message types a .msg text's fields use, in order of appearance, as full names
/// (`Type` alone is a type of `package`).
fn uses(text: &str, package: &str) -> Vec<String> {
    let mut out = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or_default().trim();
        // A field is `type name [default]`; a constant `type NAME=value` is not one (a bounded
        // type, `T[<=3]` or `string<=5`, has its `=` in the type).
        let Some((field_type, rest)) = line.split_once(char::is_whitespace) else { continue };
        if rest.trim().is_empty() || rest.contains('=') {
            continue;
        }
        // `T[]`, `T[3]`, `T[<=3]`; bounded strings `string<=5`.
        let base = field_type.split(['[', '<']).next().unwrap_or_default();
        if is_primitive(base) {
            continue;
        }
        let full = match base.split_once('/') {
            Some((pkg, name)) => format!("{pkg}/msg/{name}"),
            None => format!("{package}/msg/{base}"),
        };
        out.push(full);
    }
    out
}

/// The `ros2msg` schema of `ros_type` (`pkg/msg/Type`), or `None` for a type the node does not
/// publish. Every dependency appears once, in the order a depth-first walk meets it.
pub fn schema(ros_type: &str) -> Option<String> {
    let mut text = definition(ros_type)?.to_string();
    let mut seen = vec![ros_type.to_string()];
    let mut pending = dependencies(ros_type)?;
    while let Some(next) = pending.first().cloned() {
        pending.remove(0);
        if seen.contains(&next) {
            continue;
        }
        let body = definition(&next)?;
        let short = next.replacen("/msg/", "/", 1);
        text.push_str(&format!("\n{}\nMSG: {short}\n{body}", "=".repeat(80)));
        let mut deeper = dependencies(&next)?;
        deeper.append(&mut pending);
        pending = deeper;
        seen.push(next);
    }
    Some(text)
}

fn dependencies(ros_type: &str) -> Option<Vec<String>> {
    let package = ros_type.split('/').next()?;
    Some(uses(definition(ros_type)?, package))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_line_type_carries_its_header_and_time() {
        let s = schema("sorting_line_interfaces/msg/LineState").unwrap();
        assert!(s.starts_with(include_str!("../../msg/msg/LineState.msg")));
        let sep = "=".repeat(80);
        let header = s.find(&format!("{sep}\nMSG: std_msgs/Header\n")).expect("Header");
        let time = s.find(&format!("{sep}\nMSG: builtin_interfaces/Time\n")).expect("Time");
        assert!(header < time, "depth first");
        assert_eq!(s.matches("MSG: ").count(), 2, "{s}");
    }

    #[test]
    fn diagnostics_name_their_own_package_and_each_type_once() {
        let s = schema("diagnostic_msgs/msg/DiagnosticArray").unwrap();
        for t in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "diagnostic_msgs/DiagnosticStatus",
            "diagnostic_msgs/KeyValue",
        ] {
            assert_eq!(s.matches(&format!("MSG: {t}\n")).count(), 1, "{t} in {s}");
        }
        assert_eq!(schema("rosgraph_msgs/msg/Clock").unwrap().matches("MSG: ").count(), 1);
    }

    #[test]
    fn every_published_type_has_a_schema() {
        use crate::ros::messages::*;
        let name = |t: ros2_client::MessageTypeName| format!("{}/msg/{}", t.package_name(), t.type_name());
        for t in [
            MaterialInput::type_name(),
            BeltOccupancy::type_name(),
            MaterialRatio::type_name(),
            LineState::type_name(),
            LineStates::type_name(),
            ResetEvent::type_name(),
            EvolutionEvent::type_name(),
            Clock::type_name(),
            DiagnosticArray::type_name(),
        ] {
            let n = name(t);
            assert!(schema(&n).is_some(), "{n}");
        }
        assert_eq!(schema("geometry_msgs/msg/Pose"), None);
    }

    #[test]
    fn a_service_has_a_schema_per_part() {
        let request = schema("sorting_line_interfaces/srv/ResetLine_Request").unwrap();
        assert!(request.contains("bool has_seed") && !request.contains("success") && !request.contains("MSG: "));
        let response = schema("sorting_line_interfaces/srv/ResetLine_Response").unwrap();
        assert!(response.contains("bool success") && response.contains("MSG: builtin_interfaces/Time\n"));
    }

    #[test]
    fn constants_and_comments_are_not_fields() {
        assert_eq!(
            uses("uint8 A=1 # x\n# std_msgs/Header h\nfoo/Bar[] b\nBaz[<=3] z\n", "p"),
            ["foo/msg/Bar", "p/msg/Baz"]
        );
    }
}
