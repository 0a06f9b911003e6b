// Each moved node's watch on how far it is from where it was when the
// self-contact lists were last built, for the passes that move nodes and
// declare `p` and `lists` (read and write): `friction.wgsl`, gather's move
// without friction, and `pins.wgsl`.

// After a node moves to `at` with `velocity` (`friction.wgsl`, gather's
// move without friction, or a pin putting it at its target with none):
// ask for a rebuild when it has moved, or at this speed would have moved
// within `p.lookahead`, more than half the skin from its anchor; and flag
// the lists as possibly short of a pair when it has moved more than that.
fn watch_move(i: u32, at: vec3<f32>, velocity: vec3<f32>) {
    if (p.flags & SELF_CONTACT) == 0u {
        return;
    }
    let d = at - vec3<f32>(bitcast<f32>(lists[anchor_at(i, 0u)]), bitcast<f32>(lists[anchor_at(i, 1u)]),
                           bitcast<f32>(lists[anchor_at(i, 2u)]));
    let moved = dot3(d, d);
    // Nothing here enters a sum, so it needs none of the rounding guards.
    let margin = p.half_skin - p.lookahead * sqrt(dot(velocity, velocity));
    // A NaN fails the comparisons, so it rebuilds too.
    if !(margin >= 0.0 && moved <= margin * margin) {
        lists[STALE] = 1u;
    }
    if !(moved <= mul(p.half_skin, p.half_skin)) {
        lists[FAR] = 1u;
    }
}
