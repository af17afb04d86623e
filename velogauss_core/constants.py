"""Every numerical threshold of velogauss, in one place (spec/conventions.md, "Constants").

Both `velogauss_ref` and `velogauss_fast` import from here; changing a value is a reviewed
event because the reference, the fast path and the spec all move together. Each value
carries the reason it has that value.
"""

# --- Quaternions (VG-QUAT) -------------------------------------------------------------
# A quaternion whose squared norm is below this is treated as "no rotation" (identity)
# instead of being normalised: dividing by a norm this small amplifies rounding noise
# into an arbitrary rotation, and denormal inputs would overflow. 1e-24 is the square of
# 1e-12, far below any quaternion an optimiser produces, yet representable in float32.
QUAT_ZERO_NORM_SQ = 1e-24

# --- Projection (VG-PROJ) --------------------------------------------------------------
# Gaussians whose camera-space depth is below this are culled. 3DGS and gsplat use 0.01:
# the perspective Jacobian grows like 1/z^2, so closer Gaussians explode in screen size.
NEAR_PLANE = 0.01
# A viewing direction (VG-SH) shorter than this (world units) is taken as +z: below it the
# direction is rounding noise of the camera centre -W^T t (an FMA or a different summation
# order moves it by ~1e-16 |t| in float64, ~1e-7 |t| in float32), and such a Gaussian is
# culled anyway (its depth is below NEAR_PLANE), so its colour is a convention, not a value.
VIEW_DIRECTION_MIN = 1e-6
# Gaussians beyond this depth are culled (gsplat's default far plane); it only guards
# against inf/overflow for absurd depths.
FAR_PLANE = 1e10
# The perspective Jacobian is evaluated at x/z clamped to the image's half-extent plus
# this fraction of tan(fov/2) (1 + 0.3 = 1.3 for a centred principal point, as in 3DGS).
# Beyond the frustum the linearisation is meaningless and would stretch off-screen
# Gaussians into huge on-screen smears.
FRUSTUM_GUARD = 0.3
# Added to both diagonal entries of every 2D covariance (pixels^2): a low-pass filter that
# makes each splat at least about one pixel wide, so a Gaussian thinner than a pixel
# neither aliases nor yields a singular conic. 3DGS and gsplat use 0.3.
EPS2D = 0.3
# The dilation of the "antialiased" mode (VG-RENDER), Mip-Splatting's 2D Mip filter: about
# the variance of a one-pixel box filter (1/12), the filter a rendered pixel should apply.
# With EPS2D instead, the learned rate of strain of grow and shear stayed 3-4 % too large
# (benchmarks/FIDELITY.md, section 0c); Mip-Splatting uses 0.1.
MIP_FILTER_VARIANCE = 0.1
# Floor under det(cov2d before EPS2D) / det(cov2d), the square of the antialiased mode's
# opacity factor (VG-PROJ 5, VG-RENDER): at the floor the factor is 1e-6, so the splat's
# alpha is below ALPHA_MIN whatever its opacity and no pixel changes; the floor keeps the
# square root's derivative finite for a splat that is a line or a point on screen.
ANTIALIAS_DET_RATIO_FLOOR = 1e-12
# Screen-space extent: the splat's support is cut at this many standard deviations along
# its major axis (3 sigma holds 98.9% of a 2D Gaussian's mass). Same as 3DGS.
GAUSSIAN_EXTENT_SIGMA = 3.0
# Floor under the discriminant when computing the 2D covariance's largest eigenvalue:
# keeps the square root away from 0 (and its infinite derivative) for isotropic splats.
# Same value as 3DGS/gsplat.
EIGEN_DISCRIMINANT_FLOOR = 0.01

# --- Alpha and blending (VG-ALPHA, VG-BLEND) -------------------------------------------
# Per-splat opacity is clamped to this so that (1 - alpha) never reaches 0: the backward
# pass divides by (1 - alpha) and a single fully opaque splat would otherwise stop all
# gradients behind it. 3DGS uses 0.99.
ALPHA_MAX = 0.99
# Splat contributions with alpha below this are skipped: below one 8-bit quantisation
# step they cannot change a displayed pixel. 3DGS uses 1/255.
ALPHA_MIN = 1.0 / 255.0
# Front-to-back blending stops before the splat that would bring the transmittance below
# this: anything behind contributes less than 1e-4 of the pixel. 3DGS uses 1e-4.
TRANSMITTANCE_MIN = 1e-4
# Slack (in units of sigma) added to the row spans' pruning bound log(opacity / ALPHA_MIN)
# (VG-RENDER, velogauss_fast.spans): far above the float64 rounding of the bound itself, it
# keeps the pruning conservative when the compositing recomputes alpha in the working dtype,
# and above a last-bit difference of the bound's logarithm between the torch and compiled spans.
SPAN_SIGMA_SLACK = 0.01

# --- Photometric loss and metrics (VG-LOSS, VG-METRIC) ---------------------------------
# D-SSIM weight in the photometric loss (1 - lambda) * L1 + lambda * (1 - SSIM); 3DGS's 0.2.
LAMBDA_DSSIM = 0.2
# SSIM: Gaussian window of 11 x 11 taps with sigma 1.5 and stabilisers K1, K2 for a data
# range of 1.0 -- the values of Wang et al. (2004), used by every NeRF/3DGS evaluation.
SSIM_WINDOW = 11
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03
# PSNR of identical images would be +inf; the MSE is floored here so that PSNR is capped
# at 10 * log10(1 / 1e-10) = 100 dB and means over frames stay finite.
PSNR_MSE_FLOOR = 1e-10
# LPIPS normalises each feature channel vector by its norm plus this (lpips 0.1's value).
LPIPS_NORM_EPS = 1e-10

# --- Motion (VG-INTEG, VG-ROTSCALE, VG-ACC) --------------------------------------------
# Degree of the per-pattern polynomial in time for the acceleration coefficients: degree 2
# represents gravity (degree 0) and spin about a centre moving under gravity (degree 2)
# exactly, while a bounded degree keeps the transport residual binding on v.
ACC_POLY_DEGREE = 2
# VG-ACC-RIGID: standard deviation of each pattern's initial spin omega, in radians per unit
# of normalised time. The rigid form's acceleration is quadratic in omega (Omega^2), so at
# omega = 0 its gradient is exactly zero and the spin could never start learning. Any non-zero
# start gives the gradient a direction, and Adam's steps do not scale with its size; 0.1 keeps
# the initial centripetal term (|omega|^2 |x - c| ~ 0.01 on unit-size scenes) negligible
# against what the residual learns.
RIGID_OMEGA_INIT = 0.1
# VG-COEF-HARM: the patterns' shared frequency at the start, in cycles over the observed
# window [0, max_time], when the training video gives no estimate (velogauss.train.frequency:
# no camera saw enough times, e.g. a monocular capture). One cycle is the middle of what a
# window can identify; the frequency then converges only from about half a cycle away: the
# loss of a sinusoid fitted to an oscillation is not convex in their frequency difference.
# Started at half a cycle, pulse's frequency stopped at 6.7 rad against the true 9.4
# (benchmarks/FIDELITY.md, section 8).
HARMONIC_CYCLES_INIT = 1.0
# The scan of the training video for that starting frequency (velogauss.train.frequency):
# candidate frequencies from 1/4 cycle over the window (below that a sinusoid is a parabola)
# to 3 cycles (at least 5 frames per period with the catalogue's 16 observed frames), in
# steps of 1/40 cycle, well below the width of the scan's peak (about one cycle over the
# window), and the frames one camera must have seen in the window for its pixels to count
# (the fit has 3 unknowns per pixel: a mean, a cosine and a sine).
FREQ_SCAN_CYCLES = (0.25, 3.0)
FREQ_SCAN_STEP = 0.025
FREQ_SCAN_MIN_FRAMES = 4
# At most this many pixels per camera enter the scan, an even stride through the image: each
# pixel's series carries the frequency whole, and 65,536 of them (a 256² image) keep the
# series of a 100-frame camera at 50 MB in float64, where an 800² capture would need 500 MB.
FREQ_SCAN_PIXELS = 65536
# VG-ACC-HARM: harmonics of each pattern's frequency in its acceleration. The material
# acceleration (dL/dt + L^2) x of an oscillating affine field L(t) = a + b cos + c sin holds
# the frequencies 0, Omega (dL/dt) and 2 Omega (L^2), and nothing higher.
ACC_HARMONICS = 2
# A particle whose motion over the observed window stays below this many pixels, measured at
# its depth in the training camera that sees it largest, is "static": it is frozen at its
# canonical state and not integrated. A quarter pixel is below what the photometric loss
# resolves, yet well above the residual motion a trained field leaves on still ground
# (0.05-0.2 px on the `multi` scene's ground, against 15 px and more on its moving bodies).
STATIC_MOTION_PX = 0.25
# VG-COEF's initialisation "clusters" (velogauss.train.mixing): each initial point puts this
# weight on its k-means cluster's pattern. A probe that gave every body of `multi` its own
# pattern through a logit bias of 5 (a weight of e^5 / (e^5 + 31) = 0.83 with K = 32) learned
# the spins; 0.8 keeps the others' share large enough that a particle on a cluster that
# straddles two bodies still gets their gradient and can move to the other body's pattern.
MIXING_INIT_WEIGHT = 0.8
# Adam steps and rate of that fit (full batch over the initial points): the cross-entropy
# levels off within about 200 steps on the catalogue scenes, in about a second.
MIXING_INIT_STEPS = 300
MIXING_INIT_LR = 1e-2
# VG-COEF-RIGID's centre anchored on the body (velogauss.train.centres): the Gaussians whose
# convex hull is taken are the moving ones at least this fraction as opaque as the most
# opaque. Half keeps the body's surface (on toss at the warm-up's end, 834 Gaussians, whose
# hull centroid is 0.013 from the box's centre) and drops the faint floaters of the random
# start, which would stretch the hull; relative, so a run whose warm-up is too short to make
# anything opaque still gets a centre.
RIGID_HULL_OPACITY = 0.5
# Density control: after an opacity reset, a Gaussian whose screen radius has exceeded the larger of
# these is pruned: 3DGS's 20 px, or this share of the image's larger side (20 px at 128 px). A fixed
# 20 px at 400 px cut 5,000 of a 6,400-Gaussian reconstruction each round; the share alone (10 px)
# cost two 64 px scenes 0.9 and 1.4 dB inside the window (benchmarks/RESULTS.md, "Density control").
MAX_SCREEN_RADIUS_PX = 20
MAX_SCREEN_RADIUS_SHARE = 20 / 128
# VG-FIELD-GAUSS: a point off the Gaussians takes the mixing weights of its nearest Gaussians,
# weighted by inverse distance to this power (Shepard's interpolation; 2 is Shepard's own
# choice and the common one) over this many neighbours. Chosen before measuring, not fitted:
# on multi's two trained seeds every k in {4, 8, 16} and power in {1, 2, 3} put the velocity
# error between 0.104 and 0.138 (the code network: 0.187 and 0.204), and on the one-body
# scenes k = 8 leaves it as it was (benchmarks/FIDELITY.md, section 0e). Eight neighbours
# span a Gaussian's immediate surroundings on a surface of about 10^4 Gaussians without
# reaching across to a neighbouring body's far side.
GAUSSIAN_FIELD_NEIGHBOURS = 8
GAUSSIAN_FIELD_POWER = 2
# Distances below this (world units) count as this in the inverse-distance weights, so a query
# on a Gaussian's mean takes that Gaussian's weights (shared with any Gaussian as close)
# instead of dividing by zero. float32 positions of O(1) carry rounding of about 1e-7, so
# closer distances are noise; 1e-6 squared is far inside float32's range.
GAUSSIAN_FIELD_DISTANCE_FLOOR = 1e-6
# The fast path's topk search (off the CPU, where the k-d tree does not run) takes the query
# points in chunks of at most this many (query, Gaussian) distances: 2^24 float32 entries
# are 64 MB whatever the number of Gaussians.
GAUSSIAN_FIELD_CHUNK = 2 ** 24

# --- Data loading (velogauss.data) -----------------------------------------------------
# A camera pose is accepted as rigid when its rotation block R satisfies
# max |R^T R - I| <= this and its bottom row is (0, 0, 0, 1) to within it. Poses written by
# Blender/NeRF tools carry float32 or 6-decimal rounding (errors ~1e-6), which must pass;
# a scaled, sheared or degenerate matrix (errors ~1e-1 and up) must not, because the
# renderer's camera centre -R^T t assumes a rigid world-to-camera map.
POSE_ORTHONORMAL_TOL = 1e-3

# --- Export (velogauss.export) ---------------------------------------------------------
# 3DGS PLY files store opacity as a logit. Opacities are clamped to [this, 1 - this] before
# the logit so that a fully transparent or opaque Gaussian (sigmoid saturated in float32)
# is written as a finite value (|logit| <= 16.2) instead of -inf/+inf, which splat viewers
# reject. Only opacities within 1e-7 of 0 or 1 change, by at most 1e-7: far below ALPHA_MIN
# (1/255) and the ALPHA_MAX clamp (0.99), so no rendered pixel changes.
EXPORT_OPACITY_CLAMP = 1e-7

# --- Evaluation against synthetic ground truth (velogauss.evaluate) -------------------
# A Gaussian counts as "on" a body for the trajectory error when its canonical mean lies
# inside the body or within this distance (world units) of its surface. Trained Gaussians
# sit on or just off the surface they model, typically within a few Gaussian scales
# (about 1e-2 in the synthetic scenes); 0.05 keeps those and drops floaters. Where two
# bodies are closer than this (multi's cube rests on the ground), a Gaussian goes to the
# nearer one (AnalyticScene.body_index), so membership stays well defined.
EVAL_SURFACE_MARGIN = 0.05
# The velocity metric's relative error is undefined at a time whose true velocity vanishes.
# A periodic motion's velocity vanishes only up to rounding (pulse: cos(3π/2) ≈ -1.8e-16,
# relative to an O(1) velocity), and dividing by that noise gave relative errors of 1e14.
# Below this fraction of the largest true velocity norm over the evaluation times, a time
# has no relative error (None), as an exactly-zero one already had. Real reversal points
# sit 10 orders of magnitude above rounding in no catalogue scene, so 1e-6 separates them.
EVAL_VELOCITY_FLOOR = 1e-6
# A surface point counts as seen by a camera (velogauss.diagnose.visibility) when the analytic
# ray-caster's first hit along the ray to it lies no nearer than this fraction of its
# distance: the hit at the point itself differs from that distance by the rounding of a 3x3
# solve (about 1e-15 relative), and the nearest occluder of any catalogue surface is
# hundredths of a unit in front of it at distances of about 4, so 1e-6 separates the two.
VISIBILITY_TOLERANCE = 1e-6

# --- Inference at arbitrary times (velogauss export/render/view) ---------------------------
# |t| beyond this is refused. The model has only seen t in [0, max_time] (normalised, so
# the whole recording is [0, 1]); t = 100 is already a hundred recordings into the future,
# where the learned acceleration polynomial (degree ACC_POLY_DEGREE) dominates everything
# else. Integration cost grows linearly with |t| (|t| / model.step steps: 2000 RK2 steps at
# the default step 0.05 and t = 100, about a minute on a CPU for 10k Gaussians), so without a
# bound a mistyped time (1e6) runs for days.
TIME_HORIZON = 100.0
# Integration evaluates the time network for this many stage times at once (VG-TRAJ): at the
# default step every t in [0, 1] fits in one chunk (at most 80 RK4 stages), so training is
# unchanged, while a far time holds at most this many stages' coefficients in memory
# (256 x 12 x N floats: 120 MB for 10k Gaussians) instead of all of them.
STAGE_CHUNK = 256
# The backtest that chooses the motion patterns' form (velogauss.train.backtest, spec/motion.md,
# "Choosing the form"). The probe, a reconstruction with the time network's patterns, trains for
# this share of the run's iterations: its schedule then opens the whole window by a third of its
# length, as the run's does, and the run costs a third more.
BACKTEST_PROBE_SHARE = 1.0 / 3.0
# The candidates are fitted on the paths at t <= each of these shares of the window and scored
# on the rest (forecasting's rolling origin): a form that forecasts well only from the longest
# head fits, not predicts, and every tail keeps several frames at 16 or more.
BACKTEST_HEADS = (0.5, 0.6, 0.7)
# At most this many Gaussians' paths (a random subset of the moving, opaque ones) and frame
# times (evenly picked) enter the fits: the mean over points of a body's smooth motion is
# settled well before 1,000 of them, and 24 times resolve 3 cycles over the window.
BACKTEST_POINTS = 1000
BACKTEST_MAX_TIMES = 24
# Adam steps and starting rate of each candidate's velocity fit (decaying 100x; full batch,
# one evaluation of the field per step, a few milliseconds): the fidelity study's fit level's
# rate, and steps enough that the rigid knots, at 50x that rate, cross the scene.
BACKTEST_STEPS = 300
BACKTEST_LR = 3e-3
# The backtest's fits give each of this many clusters of paths (k-means of where each point
# starts and how it moves) a pattern of its own: enough to part 3 bodies and a ground, each
# into a few pieces, while every cluster keeps dozens of points to fit.
BACKTEST_CLUSTERS = 8
# A chosen form trains the window only if a probe trained with it renders the window's training
# frames within this many dB of the time network's probe: twice the run-to-run noise of a D-NeRF
# scene (0.5 dB, benchmarks/FIDELITY.md 0r); a form that forecasts but reconstructs worse leaves
# the window to the time network and forecasts past it from the trained paths (`model.future = "fit"`).
FORM_WINDOW_DB = 1.0
# Where the window is the time network's, the oscillators' probe takes the window only if it renders
# the window this many dB better (a quarter of the squared error): a time network that learned no
# motion that reverses was 7.5-12.6 dB behind on the tuning scenes, while a 2.0 dB gap taken cost
# a tuning scene 3.8 dB past its window (benchmarks/FIDELITY.md, 0v).
OSCILLATOR_WINDOW_DB = 6.0
# The training frames (evenly spread) whose mean PSNR says how well a probe reconstructs the window:
# a few seconds of renders at 400 px, and a mean that one odd frame does not decide.
WINDOW_FRAMES = 8
# `train.warmup_views` > 1 (monocular video): the warm-up's frames never reach past this share
# of the window, where the frozen motion would blur bodies that have moved (spec/density.md,
# "The warm-up's views").
WARMUP_WINDOW_SHARE = 0.1
# The training keeps each image's float copy and its half of SSIM (9 floats a pixel) between
# steps for at most this many bytes of images, the rest recomputed from the 8-bit pixels at each
# use: every catalogue and D-NeRF scene up to 800 px fits, while a capture of thousands of
# frames trains in bounded memory (spec/data.md, "Memory").
TARGET_CACHE_BYTES = 4 * 2**30
