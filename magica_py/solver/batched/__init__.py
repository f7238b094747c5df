"""Batched steps: teams of identical topology and parameters simulated side by side.

A crowd is many copies of a few cloths. Running one team after another makes each step a
chain of dependent scalar operations (latency-bound: docs/tech-notes.md LAYOUT measured 17-21x
between that and the same maths with the chain index innermost). Here teams that share
their topology, their per-particle model data and their parameters form a **block** of up to
``BLOCK_WIDTH`` **lanes** (one lane per team). A block's step state is stored lane-innermost
(``row = block_row_base + p * width + lane``, component-major ``(3, rows)`` arrays), so that
for each particle, edge or baseline entry of the shared topology the loop over lanes runs the
same operations on contiguous memory and LLVM vectorises it.

Bit-identity: a block stage calls the *same* per-element functions as the per-team stage
(``predict_particle``, ...) with the same inputs in the same order, and the solver's
trigonometry is branch-free polynomial (``kernels/trig.py``) rather than libm; there is no
fastmath. A block therefore produces exactly the bits the per-team path produces; the tests
compare the two on whole runs (``tests/test_batched_steps.py``).

Frame flow (``solver/frame.py``, ``simulate_frame_blocks``: a scene without blocks runs and
compiles the plain per-team kernel). A *running* block (every lane active, the same number of
steps this frame) runs its whole frame in block form: the begin of frame
(``frame.begin_frame_block``, ``frame_begin``: per lane the scalar team-level stages, docs/solver.md §C.1
skinning into the block rows, C.2 sums, the history gathered through the C.5 shift), every
step (lane-form C.3/G.3, then the block stages), the end of frame (``frame_end``: guards,
E.1 display, E.2/E.3 rotations, E.4 bone poses, on the block rows), the scatters to the team
rows and, after the barrier, the write-back through the transform indices and A.7 per lane.
A guard trip or an option the block form leaves out sends that block's end of frame to the
per-team stages (``transfer.scatter_block_end_inputs`` first). A block that cannot run this
frame (a lane culled, suspended or on another step count) leaves its teams to the per-team
path: nothing is lost, only speed.

Modules: ``blocks`` (formation, tables, Python), ``state`` (block and lane arrays),
``transfer`` (gather/scatter, per-step lane values), ``run`` (block decision per frame and
the block step), ``frame_begin`` / ``frame_end`` (the per-frame stages in block form). The block stages live next to their per-team stages (``step.predict_block``,
``constraints.angle.angle_block``, ...), calling the same per-element functions.

What a lane loop needs to vectorise (measured while writing the block stages):

* per-element maths inlined (``jit.INLINE_THRESHOLD``) and without libm (``kernels/trig``);
* the block's arrays read into locals before the loops (through the table, their pointers
  are reloaded after every store: "cannot identify array bounds");
* unsigned row indices (numba's negative-index wraparound hides the affine address:
  "unsafe indirect dependence");
* a runtime overlap-check budget above LLVM's default of 8 arrays (``jit.py``);
* branch-free per-element functions: both sides computed and selected (a slerp under a
  branch is not if-converted);
* where a loop updates many rows in place (bending's accumulators), alias scopes that tell
  LLVM which loads and stores cannot overlap (``constraints/bending.py``), or it guards the
  vector path with overlap checks that only pay off from ~40 lanes.
"""
