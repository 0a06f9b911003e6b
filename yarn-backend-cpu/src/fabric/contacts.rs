//! The live contact lists of the CPU backends: the alive contacts that
//! touch an awake block, in contact order, each node's list of them, and
//! the per-contact buffers the contact passes write.
//!
//! Released contacts and contacts asleep on both ends are left out, so
//! they cost the passes nothing. This module owns the lists; it does not
//! decide liveness (the model does) or sleep (`sleep.rs`).

use yarn_model::{ContactRest, Model, Real};

use super::field::{BLOCK, Field};

/// One node's part in a contact.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Incidence<T> {
    pub(crate) node: u32,
    /// The contact's slot in [`LiveContacts::live`].
    pub(crate) contact: u32,
    /// +1 if the node is the contact's `a`, −1 if its `b`.
    pub(crate) sign: T,
}

/// The contacts the passes run over.
#[derive(Debug, Default)]
pub(crate) struct LiveContacts<T> {
    /// The alive contacts with a node in an awake block, in contact order.
    pub(crate) live: Vec<ContactRest<T>>,
    /// Each contact's slot in `live`, or `u32::MAX` when it is not there.
    slot: Vec<u32>,
    /// The live contacts of node i are `incident[start[i]..start[i + 1]]`.
    start: Vec<u32>,
    incident: Vec<Incidence<T>>,
    /// Per live contact, in blocks of [`BLOCK`] contacts: the force on its
    /// `a` node, then the friction change Δw.
    pub(crate) force: Field<T>,
    pub(crate) friction: Field<T>,
}

impl<T: Real> LiveContacts<T> {
    /// Rebuild the lists from `model`'s alive contacts, keeping those with
    /// a node in a block that `asleep` says is awake.
    pub(crate) fn refresh(&mut self, model: &Model<T>, asleep: &[bool]) {
        let (_, entries) = model.incidence();
        let awake = |node: u32| !asleep[node as usize / BLOCK];
        let contacts = model.contacts();
        let mut slot = vec![u32::MAX; contacts.len()];
        self.live.clear();
        for (k, c) in contacts.iter().enumerate() {
            if model.alive()[k] && (awake(c.a) || awake(c.b)) {
                slot[k] = self.live.len() as u32;
                self.live.push(*c);
            }
        }
        let mut start = vec![0u32; model.node_count() + 1];
        self.incident = entries
            .into_iter()
            .filter(|&(_, contact)| slot[contact as usize] != u32::MAX)
            .map(|(node, contact)| {
                start[node as usize + 1] += 1;
                let sign = if contacts[contact as usize].a == node { T::one() } else { -T::one() };
                Incidence { node, contact: slot[contact as usize], sign }
            })
            .collect();
        for i in 0..model.node_count() {
            start[i + 1] += start[i];
        }
        self.start = start;
        self.slot = slot;
        self.force = Field::zeros(self.live.len());
        self.friction = Field::zeros(self.live.len());
    }

    /// A re-seated contact's new rest separation, where it is live.
    pub(crate) fn set_rest(&mut self, contact: u32, rest: T) {
        if let Some(c) = self.live.get_mut(self.slot[contact as usize] as usize) {
            c.rest = rest;
        }
    }

    /// The contact entries of block `block`'s nodes, one group per node
    /// that has contacts, each in contact order.
    pub(crate) fn groups(&self, block: usize) -> impl Iterator<Item = &[Incidence<T>]> {
        let (lo, hi) = (block * BLOCK, ((block + 1) * BLOCK).min(self.start.len() - 1));
        self.incident[self.start[lo] as usize..self.start[hi] as usize].chunk_by(|p, q| p.node == q.node)
    }
}
