// Each moved node's watch on how far it is from where it was when the
// self-contact lists were last built, for the passes that move nodes and
// declare `p` and `lists` (read and write): `friction.wgsl`, gather's move
// without friction, and `pins.wgsl`.

// After a node moves to `at` (`friction.wgsl`, gather's move without
// friction, or a pin putting it at its target): flag a rebuild when it has
// moved more than half the skin from its anchor.
fn watch_move(i: u32, at: vec3<f32>) {
    if (p.flags & SELF_CONTACT) == 0u {
        return;
    }
    let d = at - vec3<f32>(bitcast<f32>(lists[anchor_at(i, 0u)]), bitcast<f32>(lists[anchor_at(i, 1u)]),
                           bitcast<f32>(lists[anchor_at(i, 2u)]));
    // A NaN fails the comparison, so it rebuilds too.
    if !(dot3(d, d) <= mul(p.half_skin, p.half_skin)) {
        lists[STALE] = 1u;
    }
}
