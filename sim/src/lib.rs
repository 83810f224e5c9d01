//! The other side of every wire: contact plant, robot inner-loop models, sensor models, simulated peers.

pub mod ati_node;

pub fn placeholder() {}
