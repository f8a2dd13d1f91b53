//! Which of a model's declared inputs its graph actually reads.
//!
//! ONNX Runtime lists a graph's inputs, and every one must be fed, but it does not say whether any
//! node consumes them. A network may declare the contract's occupancy image and never read it
//! (the pair-potential network reads only its neighbours and scalars). The agent then need not
//! render that image on every tick: rendering a 50 x 50 window costs more than the whole
//! inference of such a network.
//!
//! This module decodes just enough of the ONNX protobuf (`ModelProto.graph`, each node's inputs
//! and the subgraphs of control-flow nodes) to answer "does anything read input `name`?". Every
//! other field is skipped by the decoder without being kept.

use std::collections::BTreeSet;

use prost::Message;

/// `onnx.ModelProto`, only its graph.
#[derive(Clone, PartialEq, Message)]
struct ModelProto {
    #[prost(message, optional, tag = "7")]
    graph: Option<GraphProto>,
}

/// `onnx.GraphProto`, only its nodes and outputs.
#[derive(Clone, PartialEq, Message)]
struct GraphProto {
    #[prost(message, repeated, tag = "1")]
    node: Vec<NodeProto>,
    #[prost(message, repeated, tag = "12")]
    output: Vec<ValueInfoProto>,
}

/// `onnx.NodeProto`, only its inputs and attributes (where subgraphs live).
#[derive(Clone, PartialEq, Message)]
struct NodeProto {
    #[prost(string, repeated, tag = "1")]
    input: Vec<String>,
    #[prost(message, repeated, tag = "5")]
    attribute: Vec<AttributeProto>,
}

/// `onnx.AttributeProto`, only its graph values (the bodies of `If`, `Loop` and `Scan`).
#[derive(Clone, PartialEq, Message)]
struct AttributeProto {
    #[prost(message, optional, tag = "6")]
    g: Option<GraphProto>,
    #[prost(message, repeated, tag = "11")]
    graphs: Vec<GraphProto>,
}

/// `onnx.ValueInfoProto`, only its name.
#[derive(Clone, PartialEq, Message)]
struct ValueInfoProto {
    #[prost(string, tag = "1")]
    name: String,
}

/// The names a graph reads: every node's inputs, in it and in its subgraphs, and its outputs
/// (an input passed straight through is read too).
fn names_read(graph: &GraphProto, read: &mut BTreeSet<String>) {
    read.extend(graph.output.iter().map(|o| o.name.clone()));
    for node in &graph.node {
        read.extend(node.input.iter().cloned());
        for attribute in &node.attribute {
            for sub in attribute.g.iter().chain(&attribute.graphs) {
                names_read(sub, read);
            }
        }
    }
}

/// Whether the ONNX model in `bytes` reads its graph input `name`. A model that cannot be decoded
/// counts as reading everything: the answer only ever lets a caller skip work, never feed less.
pub(crate) fn reads_input(bytes: &[u8], name: &str) -> bool {
    let Ok(model) = ModelProto::decode(bytes) else {
        return true;
    };
    let Some(graph) = model.graph else {
        return true;
    };
    let mut read = BTreeSet::new();
    names_read(&graph, &mut read);
    read.contains(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(inputs: &[&str]) -> NodeProto {
        NodeProto {
            input: inputs.iter().map(|s| (*s).to_owned()).collect(),
            attribute: Vec::new(),
        }
    }

    fn model(graph: GraphProto) -> Vec<u8> {
        ModelProto { graph: Some(graph) }.encode_to_vec()
    }

    #[test]
    fn an_input_no_node_consumes_is_not_read() {
        let bytes = model(GraphProto {
            node: vec![node(&["aux", "w0"]), node(&["neighbours", "h"])],
            output: Vec::new(),
        });
        assert!(reads_input(&bytes, "aux"));
        assert!(reads_input(&bytes, "neighbours"));
        assert!(!reads_input(&bytes, "occupancy"));
    }

    #[test]
    fn an_input_read_inside_a_subgraph_or_passed_through_is_read() {
        let body = GraphProto {
            node: vec![node(&["occupancy"])],
            output: Vec::new(),
        };
        let branch = NodeProto {
            input: vec!["condition".to_owned()],
            attribute: vec![AttributeProto {
                g: Some(body),
                graphs: Vec::new(),
            }],
        };
        let bytes = model(GraphProto {
            node: vec![branch],
            output: vec![ValueInfoProto {
                name: "aux".to_owned(),
            }],
        });
        assert!(reads_input(&bytes, "occupancy"), "read in the If body");
        assert!(reads_input(&bytes, "aux"), "passed straight to an output");
    }

    #[test]
    fn bytes_that_are_not_a_model_count_as_reading_everything() {
        assert!(reads_input(b"\xff\xff\xff not protobuf", "occupancy"));
        assert!(reads_input(&[], "occupancy"), "no graph at all");
    }

    #[test]
    fn the_shipped_models_read_what_their_architecture_does() {
        let models = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
        let pair = std::fs::read(models.join("policy.onnx")).expect("the shipped default");
        assert!(!reads_input(&pair, crate::contract::OCCUPANCY_INPUT));
        assert!(reads_input(&pair, crate::contract::NEIGHBOURS_INPUT));
        let image = std::fs::read(models.join("wide-head/policy.onnx")).expect("the image model");
        assert!(reads_input(&image, crate::contract::OCCUPANCY_INPUT));
    }
}
