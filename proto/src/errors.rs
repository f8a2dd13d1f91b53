//! How the binaries print an error: its message, then each of its sources, joined by ": ".
//!
//! Some error types name their source in their own message as well as returning it from
//! `Error::source`, so walking the chain naively (`anyhow`'s `{:#}`) prints the same cause twice.
//! [`chain_text`] skips a source whose text the message so far already contains.

use std::error::Error;

/// `error` and its sources as one line, without repeating a source that a message embeds.
pub fn chain_text(error: &(dyn Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        let cause_text = cause.to_string();
        if !cause_text.is_empty() && !text.contains(&cause_text) {
            text.push_str(": ");
            text.push_str(&cause_text);
        }
        source = cause.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug)]
    struct Layer {
        message: String,
        source: Option<Box<Layer>>,
    }

    impl std::fmt::Display for Layer {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str(&self.message)
        }
    }

    impl Error for Layer {
        fn source(&self) -> Option<&(dyn Error + 'static)> {
            self.source.as_deref().map(|s| s as &(dyn Error + 'static))
        }
    }

    fn layer(message: &str, source: Option<Layer>) -> Layer {
        Layer {
            message: message.to_owned(),
            source: source.map(Box::new),
        }
    }

    #[test]
    fn a_source_that_its_message_embeds_is_printed_once() {
        let inner = layer("model \"m.onnx\" not found", None);
        let outer = layer(
            "cannot load the policy's models: model \"m.onnx\" not found",
            Some(inner),
        );
        let top = layer("starting DAgger", Some(outer));
        assert_eq!(
            chain_text(&top),
            "starting DAgger: cannot load the policy's models: model \"m.onnx\" not found"
        );
        // Also when the message goes on after naming it.
        let io = layer("No such file or directory (os error 2)", None);
        let read = layer(
            "cannot read a.toml: No such file or directory (os error 2); check the path",
            Some(io),
        );
        assert_eq!(
            chain_text(&read),
            "cannot read a.toml: No such file or directory (os error 2); check the path"
        );
    }

    #[test]
    fn sources_that_add_something_are_all_printed() {
        let io = layer("permission denied", None);
        let top = layer(
            "reading scenarios/a.toml",
            Some(layer("opening it", Some(io))),
        );
        assert_eq!(
            chain_text(&top),
            "reading scenarios/a.toml: opening it: permission denied"
        );
    }
}
