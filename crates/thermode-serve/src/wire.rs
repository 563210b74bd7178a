//! The one converter between the loop core's vocabulary and the wire's: the core (`thermode_runtime`) names who owns
//! a channel, what it renders and a response's kind in its own types, and links no protocol crate; the daemon
//! translates here, at its edge, both ways.

use thermode_protocol as wire;
use thermode_runtime::command::{Owner, ResponseKind};
use thermode_runtime::snapshot::Mode;

/// A channel's mode as the wire spells it.
pub fn mode(mode: Mode) -> wire::Mode {
    match mode {
        Mode::Air => wire::Mode::Air,
        Mode::Touch => wire::Mode::Touch,
        Mode::Direct => wire::Mode::Direct,
    }
}

/// A channel's owner as the wire spells it.
pub fn owner(owner: Owner) -> wire::Owner {
    match owner {
        Owner::Nobody => wire::Owner::Nobody,
        Owner::Client(id) => wire::Owner::Client(id),
        Owner::Osc => wire::Owner::Osc,
        Owner::Script => wire::Owner::Script,
    }
}

/// A response's kind as the wire spells it.
pub fn response_kind(kind: ResponseKind) -> wire::ResponseKind {
    match kind {
        ResponseKind::Button => wire::ResponseKind::Button,
        ResponseKind::Rating => wire::ResponseKind::Rating,
    }
}

/// A response's kind as the loop takes it.
pub fn loop_response_kind(kind: wire::ResponseKind) -> ResponseKind {
    match kind {
        wire::ResponseKind::Button => ResponseKind::Button,
        wire::ResponseKind::Rating => ResponseKind::Rating,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn json(value: impl serde::Serialize) -> String {
        serde_json::to_string(&value).unwrap_or_default()
    }

    #[test]
    fn every_word_goes_to_its_namesake_on_the_wire_and_back() {
        for kind in [ResponseKind::Button, ResponseKind::Rating] {
            assert_eq!(loop_response_kind(response_kind(kind)), kind);
        }
        let modes = [Mode::Air, Mode::Touch, Mode::Direct].map(|m| json(mode(m)));
        assert_eq!(modes, [r#""air""#, r#""touch""#, r#""direct""#]);
        let owners = [Owner::Nobody, Owner::Client(7), Owner::Osc, Owner::Script].map(|o| json(owner(o)));
        let expected = [
            r#"{"kind":"nobody"}"#,
            r#"{"kind":"client","id":7}"#,
            r#"{"kind":"osc"}"#,
            r#"{"kind":"script"}"#,
        ];
        assert_eq!(owners, expected);
        assert_eq!(json(response_kind(ResponseKind::Rating)), r#""rating""#);
    }
}
