// Before the list passes of a substep that may rebuild (every substep in
// the browser, every `CADENCE`-th natively: `record.rs`): whether the
// candidate lists must be rebuilt, because some node has moved, or soon
// will have moved, half the skin since the last build (`lists[STALE]`, set
// by the move) or the host asked,
// as the workgroup counts of the indirect dispatches of `grid_insert.wgsl`
// and `grid_find.wgsl`: all of them, or none. A rebuild starts a new
// generation of bucket heads and an empty long list, and the lists it
// makes hold every pair within reach again (`lists[FAR]`). One thread.

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> lists: array<u32>;
@group(0) @binding(2) var<storage, read_write> grid: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> rebuild: array<u32>;

@compute @workgroup_size(1)
fn main() {
    let stale = lists[STALE] != 0u;
    lists[STALE] = 0u;
    rebuild[0] = select(0u, p.rebuild_x, stale);
    rebuild[1] = select(0u, p.rebuild_y, stale);
    rebuild[2] = 1u;
    if stale {
        atomicAdd(&grid[GENERATION], 1u);
        atomicStore(&grid[LONG_COUNT], 0u);
        lists[FAR] = 0u;
    }
}
