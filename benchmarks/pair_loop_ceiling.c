/* What a fused pair loop costs on this CPU: the step of benchmarks/throughput.py's
 * Taylor-Green (periodic unit square, n x n particles, quintic spline, h = dx, support 3 h,
 * summation density, linear equation of state, Morris viscosity (mu = rho nu), kick-drift-kick with one
 * right-hand side per step), written as plain loops over a cell list rebuilt every step.
 * Not part of sphjax: a ceiling to set the XLA step against (benchmarks/pair_loop_ceiling.py
 * compiles and runs it).  float32, particles re-sorted by cell every step, each pair visited
 * from both sides (no symmetry), OpenMP over particles.
 *
 *   usage: pair_loop_ceiling N STEPS [SPLIT [MODE]]: SPLIT cells per support length
 *   (default 1); MODE 0: every pair from both sides, OpenMP over particles (default);
 *   1: each pair visited once, one thread; 2: cell-blocked, each pair once, vectorised
 *   over contiguous runs of cells, OpenMP over stripes of cells (see Run below); 3: the
 *   same, BLOCK particles a at a time against each run
 *   ->  prints one line of key=value figures
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>
#endif

typedef float real;

static double now(clockid_t clock) {
    struct timespec t;
    clock_gettime(clock, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static inline real wrap(real d) { /* minimum image on the unit square */
    return d - rintf(d);
}

static inline real positive(real a) { /* max(a, 0), a compare and select in a vector loop */
    return a > 0 ? a : 0;
}

/* quintic spline f(q) = (3-q)^5 - 6 (2-q)^5 + 15 (1-q)^5 (each term where positive) */
static inline real shape(real q) {
    real q3 = positive(3 - q), q2 = positive(2 - q), q1 = positive(1 - q);
    real q3_2 = q3 * q3, q2_2 = q2 * q2, q1_2 = q1 * q1;
    return q3_2 * q3_2 * q3 - 6 * q2_2 * q2_2 * q2 + 15 * q1_2 * q1_2 * q1;
}

/* its derivative f'(q) */
static inline real shape_derivative(real q) {
    real q3 = positive(3 - q), q2 = positive(2 - q), q1 = positive(1 - q);
    return -5 * q3 * q3 * q3 * q3 + 30 * q2 * q2 * q2 * q2 - 75 * q1 * q1 * q1 * q1;
}

/* ---- the cell-blocked loop (MODE 2) ----
 * The particles are stored in cell order (cell id = row * nc + column), so the cells of
 * one row from column c0 to c1 hold one contiguous run of particles.  For each particle a
 * the half shell of its cell (its own cell and the next SPLIT cells of its row, then the
 * 2 SPLIT + 1 cells of each of the next SPLIT rows) is at most 2 (SPLIT + 1) such runs;
 * the loop over a run's particles b is unit-stride, rounded up to whole vectors of LANES
 * floats, with the pairs outside the support (and the lanes past the run) masked: no
 * neighbour list, no gather.  Each pair is visited once (in a's own cell only b > a) and
 * its terms are added to both particles: b's by a masked store into the run, a's to one
 * vector of partial sums kept over all its runs and added up once. */
enum { LANES = 8 };    /* floats per 256-bit (AVX2) vector; the arrays are padded by as many */
enum { MAX_SPLIT = 4 }; /* cells per support length, at most */

typedef struct {     /* a run of particles b in cell order, lo <= b < hi */
    int lo, hi;
    int own;         /* 1: the run starts with a's own cell, so only b > a pair with a */
    real shift_x, shift_y; /* its periodic image: r_a - r_b = (x_a - x_b - shift_x, ...) */
} Run;

typedef struct { /* the fluid in cell order (structure of arrays) and the step's constants */
    int nc, split;
    int block;        /* 1: BLOCK particles a at a time (MODE 3) */
    const int *start; /* cell c holds the particles start[c] <= a < start[c + 1] */
    const real *x, *y, *u, *v, *coef, *inv; /* coef = p / rho^2, inv = 1 / rho */
    real *rho, *ax, *ay; /* the sums: the kernel sum, then the acceleration */
    real h, support2, sigma, m, nu, eta2;
} Fluid;

/* the particles of row `row` (SPLIT rows at most past the last, taken periodically) from
 * column c0 to c1 (at most SPLIT columns past either end) as one or two runs */
static int strip(const Fluid *f, int row, int c0, int c1, int own, Run *runs) {
    int nc = f->nc, count = 0;
    real shift_x = row >= nc ? 1 : 0; /* a's row is near 1, this one near 0 */
    row %= nc;
    const int *start = f->start + row * nc;
    if (c0 < 0) { /* the columns left of 0 are the last ones, their images at y - 1 */
        runs[count++] = (Run){start[c0 + nc], start[nc], own, shift_x, -1};
        c0 = 0, own = 0;
    }
    int last = c1 < nc ? c1 : nc - 1;
    runs[count++] = (Run){start[c0], start[last + 1], own, shift_x, 0};
    if (c1 >= nc) /* the columns past the last are the first ones, their images at y + 1 */
        runs[count++] = (Run){start[0], start[c1 - nc + 1], 0, shift_x, 1};
    return count;
}

/* the half shell of cell (row, column) as runs; their count */
static int half_shell(const Fluid *f, int row, int column, Run *runs) {
    int count = strip(f, row, column, column + f->split, 1, runs);
    for (int di = 1; di <= f->split; di++)
        count += strip(f, row + di, column - f->split, column + f->split, 0, runs + count);
    return count;
}

/* eq. 5's kernel sum for a against one run: sum_b f(|r_ab| / h), added to a's LANES
 * partial sums sum_lanes[] (one vector, summed once a has met all its runs) and to rho[b]
 * for each b in the support; counts[0] counts the pairs, counts[1] the distances
 * evaluated (the lanes) */
static void kernel_sum(const Fluid *f, int a, Run run, long long *counts,
                       real *restrict sum_lanes) {
    const real *restrict x = f->x, *restrict y = f->y;
    real *restrict rho = f->rho;
    real xa = x[a] - run.shift_x, ya = y[a] - run.shift_y;
    real support2 = f->support2, inverse_h = 1 / f->h;
    int first = run.own ? a + 1 : run.lo, hi = run.hi, count = 0;
    int end = run.lo + (hi - run.lo + LANES - 1) / LANES * LANES; /* whole vectors */
    for (int b0 = run.lo; b0 < end; b0 += LANES) { /* one vector of particles b */
#pragma omp simd simdlen(LANES) reduction(+ : count)
        for (int k = 0; k < LANES; k++) {
            int b = b0 + k;
            real rx = xa - x[b], ry = ya - y[b], r2 = rx * rx + ry * ry;
            int pair = b >= first && b < hi && r2 < support2;
            real w = pair ? shape(sqrtf(r2) * inverse_h) : 0;
            sum_lanes[k] += w;
            count += pair;
            if (pair) rho[b] += w;
        }
    }
    counts[0] += count;
    counts[1] += end - run.lo;
}

/* eq. 10 with Morris' viscosity for a against one run: the pair's acceleration of a,
 * -m (p_a / rho_a^2 + p_b / rho_b^2) grad W + m nu (1/rho_a + 1/rho_b) r.grad W /
 * (r^2 + eta^2) (v_a - v_b), added to a's partial sums gx[], gy[] (as kernel_sum's) and
 * subtracted from b's (equal masses) */
static void momentum_sum(const Fluid *f, int a, Run run, real *restrict gx,
                         real *restrict gy) {
    const real *restrict x = f->x, *restrict y = f->y, *restrict u = f->u, *restrict v = f->v;
    const real *restrict coef = f->coef, *restrict inv = f->inv;
    real *restrict ax = f->ax, *restrict ay = f->ay;
    real support2 = f->support2, inverse_h = 1 / f->h, eta2 = f->eta2, m = f->m;
    real xa = x[a] - run.shift_x, ya = y[a] - run.shift_y;
    real ua = u[a], va = v[a], coef_a = coef[a], inv_a = inv[a];
    real gradient_scale = f->sigma / f->h, viscous_scale = f->m * f->nu;
    int first = run.own ? a + 1 : run.lo, hi = run.hi;
    int end = run.lo + (hi - run.lo + LANES - 1) / LANES * LANES;
    for (int b0 = run.lo; b0 < end; b0 += LANES) { /* one vector of particles b */
#pragma omp simd simdlen(LANES)
        for (int k = 0; k < LANES; k++) {
            int b = b0 + k;
            real rx = xa - x[b], ry = ya - y[b], r2 = rx * rx + ry * ry;
            int pair = b >= first && b < hi && r2 < support2;
            real r = sqrtf(r2), dw = shape_derivative(r * inverse_h);
            real grad = pair && r > 0 ? gradient_scale * dw / r : 0; /* grad W = grad r_ab */
            real pressure = -m * (coef_a + coef[b]);
            real viscous = viscous_scale * (inv_a + inv[b]) * (r2 * grad) / (r2 + eta2);
            real fx = pressure * grad * rx + viscous * (ua - u[b]);
            real fy = pressure * grad * ry + viscous * (va - v[b]);
            gx[k] += fx;
            gy[k] += fy;
            if (pair) {
                ax[b] -= fx;
                ay[b] -= fy;
            }
        }
    }
}

/* ---- the same with BLOCK = 4 particles a at a time (MODE 3) ----
 * Four consecutive particles a of one cell go through a run together: each b's fields are
 * loaded once for all four and its four terms summed in registers before the one masked
 * store.  Particles of the block past the cell's end take no pairs. */
enum { BLOCK = 4 };

/* the kernel sum's term f(|r_ab| / h) of one pair (0 where it is not a pair); *pairs
 * counts the pairs */
static inline real kernel_term(real rx, real ry, int pair, real support2, real inverse_h,
                               int *pairs) {
    real r2 = rx * rx + ry * ry;
    pair = pair && r2 < support2;
    *pairs += pair;
    return pair ? shape(sqrtf(r2) * inverse_h) : 0;
}

/* the momentum's term of one pair (momentum_sum's, 0 where it is not a pair): a's
 * acceleration (*fx, *fy) */
static inline void momentum_term(const Fluid *f, real rx, real ry, int pair, real coef_ab,
                                 real inv_ab, real du, real dv, real *fx, real *fy) {
    real r2 = rx * rx + ry * ry, r = sqrtf(r2), dw = shape_derivative(r * (1 / f->h));
    real grad = pair && r2 < f->support2 && r > 0 ? f->sigma / f->h * dw / r : 0;
    real pressure = -f->m * coef_ab;
    real viscous = f->m * f->nu * inv_ab * (r2 * grad) / (r2 + f->eta2);
    *fx = pressure * grad * rx + viscous * du;
    *fy = pressure * grad * ry + viscous * dv;
}

/* kernel_sum for particles a0 .. a0 + na - 1 (na <= 4): their sums added to sum[] */
static void kernel_sum_block(const Fluid *f, int a0, int na, Run run, real *sum,
                             long long *counts) {
    const real *restrict x = f->x, *restrict y = f->y;
    real *restrict rho = f->rho;
    real support2 = f->support2, inverse_h = 1 / f->h;
    real xa[BLOCK], ya[BLOCK];
    int first[BLOCK], hi = run.hi;
    for (int k = 0; k < BLOCK; k++) {
        int a = a0 + (k < na ? k : 0);
        xa[k] = x[a] - run.shift_x;
        ya[k] = y[a] - run.shift_y;
        first[k] = k >= na ? hi : run.own ? a + 1 : run.lo; /* b >= first[k] pairs */
    }
    int lo = run.own ? a0 + 1 : run.lo;
    int end = lo + (hi - lo + LANES - 1) / LANES * LANES;
    real s0 = 0, s1 = 0, s2 = 0, s3 = 0;
    int count = 0;
#pragma omp simd simdlen(LANES) reduction(+ : s0, s1, s2, s3, count)
    for (int b = lo; b < end; b++) {
        real xb = x[b], yb = y[b];
        int in_run = b < hi;
        real w0 = kernel_term(xa[0] - xb, ya[0] - yb, in_run && b >= first[0], support2,
                              inverse_h, &count);
        real w1 = kernel_term(xa[1] - xb, ya[1] - yb, in_run && b >= first[1], support2,
                              inverse_h, &count);
        real w2 = kernel_term(xa[2] - xb, ya[2] - yb, in_run && b >= first[2], support2,
                              inverse_h, &count);
        real w3 = kernel_term(xa[3] - xb, ya[3] - yb, in_run && b >= first[3], support2,
                              inverse_h, &count);
        s0 += w0, s1 += w1, s2 += w2, s3 += w3;
        if (in_run) rho[b] += w0 + w1 + w2 + w3;
    }
    sum[0] += s0, sum[1] += s1, sum[2] += s2, sum[3] += s3;
    counts[0] += count;
    counts[1] += end - lo; /* whole vectors, each for four particles a */
}

/* momentum_sum for particles a0 .. a0 + na - 1: their accelerations added to gx[], gy[] */
static void momentum_sum_block(const Fluid *f, int a0, int na, Run run, real *gx, real *gy) {
    const real *restrict x = f->x, *restrict y = f->y, *restrict u = f->u, *restrict v = f->v;
    const real *restrict coef = f->coef, *restrict inv = f->inv;
    real *restrict ax = f->ax, *restrict ay = f->ay;
    real xa[BLOCK], ya[BLOCK], ua[BLOCK], va[BLOCK], coef_a[BLOCK], inv_a[BLOCK];
    int first[BLOCK], hi = run.hi;
    for (int k = 0; k < BLOCK; k++) {
        int a = a0 + (k < na ? k : 0);
        xa[k] = x[a] - run.shift_x;
        ya[k] = y[a] - run.shift_y;
        ua[k] = u[a], va[k] = v[a], coef_a[k] = coef[a], inv_a[k] = inv[a];
        first[k] = k >= na ? hi : run.own ? a + 1 : run.lo;
    }
    int lo = run.own ? a0 + 1 : run.lo;
    int end = lo + (hi - lo + LANES - 1) / LANES * LANES;
    real x0 = 0, x1 = 0, x2 = 0, x3 = 0, y0 = 0, y1 = 0, y2 = 0, y3 = 0;
#pragma omp simd simdlen(LANES) reduction(+ : x0, x1, x2, x3, y0, y1, y2, y3)
    for (int b = lo; b < end; b++) {
        real xb = x[b], yb = y[b], ub = u[b], vb = v[b], coef_b = coef[b], inv_b = inv[b];
        int in_run = b < hi;
        real fx0, fy0, fx1, fy1, fx2, fy2, fx3, fy3;
        momentum_term(f, xa[0] - xb, ya[0] - yb, in_run && b >= first[0], coef_a[0] + coef_b,
                      inv_a[0] + inv_b, ua[0] - ub, va[0] - vb, &fx0, &fy0);
        momentum_term(f, xa[1] - xb, ya[1] - yb, in_run && b >= first[1], coef_a[1] + coef_b,
                      inv_a[1] + inv_b, ua[1] - ub, va[1] - vb, &fx1, &fy1);
        momentum_term(f, xa[2] - xb, ya[2] - yb, in_run && b >= first[2], coef_a[2] + coef_b,
                      inv_a[2] + inv_b, ua[2] - ub, va[2] - vb, &fx2, &fy2);
        momentum_term(f, xa[3] - xb, ya[3] - yb, in_run && b >= first[3], coef_a[3] + coef_b,
                      inv_a[3] + inv_b, ua[3] - ub, va[3] - vb, &fx3, &fy3);
        x0 += fx0, x1 += fx1, x2 += fx2, x3 += fx3;
        y0 += fy0, y1 += fy1, y2 += fy2, y3 += fy3;
        if (in_run) {
            ax[b] -= fx0 + fx1 + fx2 + fx3;
            ay[b] -= fy0 + fy1 + fy2 + fy3;
        }
    }
    gx[0] += x0, gx[1] += x1, gx[2] += x2, gx[3] += x3;
    gy[0] += y0, gy[1] += y1, gy[2] += y2, gy[3] += y3;
}

/* the kernel sums of the particles of rows [row0, row1) against their half shells (counts:
 * as kernel_sum's), one particle a at a time or BLOCK (f->block) */
static void kernel_sum_rows(const Fluid *f, int row0, int row1, long long *counts) {
    Run runs[2 * (MAX_SPLIT + 1)];
    for (int row = row0; row < row1; row++)
        for (int column = 0; column < f->nc; column++) {
            int c = row * f->nc + column, count = half_shell(f, row, column, runs);
            if (!f->block) {
                for (int a = f->start[c]; a < f->start[c + 1]; a++) {
                    real sum_lanes[LANES] = {0}, sum = 0;
                    for (int k = 0; k < count; k++) kernel_sum(f, a, runs[k], counts, sum_lanes);
                    for (int k = 0; k < LANES; k++) sum += sum_lanes[k];
                    f->rho[a] += sum;
                }
                continue;
            }
            for (int a0 = f->start[c]; a0 < f->start[c + 1]; a0 += BLOCK) {
                int na = f->start[c + 1] - a0 < BLOCK ? f->start[c + 1] - a0 : BLOCK;
                real sum[BLOCK] = {0};
                for (int k = 0; k < count; k++) kernel_sum_block(f, a0, na, runs[k], sum, counts);
                for (int k = 0; k < na; k++) f->rho[a0 + k] += sum[k];
            }
        }
}

/* the same for the momentum */
static void momentum_sum_rows(const Fluid *f, int row0, int row1, long long *counts) {
    Run runs[2 * (MAX_SPLIT + 1)];
    for (int row = row0; row < row1; row++)
        for (int column = 0; column < f->nc; column++) {
            int c = row * f->nc + column, count = half_shell(f, row, column, runs);
            if (!f->block) {
                for (int a = f->start[c]; a < f->start[c + 1]; a++) {
                    real gx[LANES] = {0}, gy[LANES] = {0};
                    for (int k = 0; k < count; k++) momentum_sum(f, a, runs[k], gx, gy);
                    for (int k = 0; k < LANES; k++) {
                        f->ax[a] += gx[k];
                        f->ay[a] += gy[k];
                    }
                }
                continue;
            }
            for (int a0 = f->start[c]; a0 < f->start[c + 1]; a0 += BLOCK) {
                int na = f->start[c + 1] - a0 < BLOCK ? f->start[c + 1] - a0 : BLOCK;
                real gx[BLOCK] = {0}, gy[BLOCK] = {0};
                for (int k = 0; k < count; k++) momentum_sum_block(f, a0, na, runs[k], gx, gy);
                for (int k = 0; k < na; k++) {
                    f->ax[a0 + k] += gx[k];
                    f->ay[a0 + k] += gy[k];
                }
            }
        }
    (void)counts;
}

/* One pass over all rows of cells, threads over stripes of rows: each thread first does
 * its stripe's rows but the last SPLIT (their half shells stay in the stripe), then, after
 * a barrier, those last SPLIT rows (their half shells reach SPLIT rows into the next
 * stripe, rows no other thread's last rows reach), so no two threads ever add to the same
 * particle.  Stripes narrower than 2 SPLIT rows: one thread.  counts: rows' counts, summed. */
static void over_stripes(const Fluid *f, void (*rows)(const Fluid *, int, int, long long *),
                         long long *counts) {
    long long inside = 0, lanes = 0;
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    if (f->nc / threads < 2 * f->split) threads = 1;
#pragma omp parallel num_threads(threads) reduction(+ : inside, lanes)
    {
        long long mine[2] = {0, 0};
        int t = 0;
#ifdef _OPENMP
        t = omp_get_thread_num();
#endif
        int first = f->nc * t / threads, last = f->nc * (t + 1) / threads;
        if (threads == 1) {
            rows(f, 0, f->nc, mine);
        } else {
            rows(f, first, last - f->split, mine);
#pragma omp barrier
            rows(f, last - f->split, last, mine);
        }
        inside += mine[0];
        lanes += mine[1];
    }
    counts[0] += inside;
    counts[1] += lanes;
}

int main(int argc, char **argv) {
    int n = argc > 1 ? atoi(argv[1]) : 200, steps = argc > 2 ? atoi(argv[2]) : 50;
    int N = n * n;
    real dx = 1.0f / n, h = dx, support = 3.0f * h, U = 1.0f, c0 = 10.0f * U, rho0 = 1.0f;
    real nu = 0.01f, m = rho0 * dx * dx, dt = 0.25f * h / (c0 + U);
    real support2 = support * support;
    real sigma = 7.0f / (478.0f * (real)M_PI * h * h), eta2 = 0.01f * h * h;
    int mode = argc > 4 ? atoi(argv[4]) : 0; /* 1: each pair once; 2, 3: cell-blocked */
    int split = argc > 3 ? atoi(argv[3]) : 1; /* cells per support length */
    int nc = (int)floorf(split / support); /* cells per side, each at least support / split */
    real cell = 1.0f / nc;
    int ncell = nc * nc;
    if (split < 1 || split > MAX_SPLIT || nc < 2 * split + 1) {
        fprintf(stderr, "SPLIT %d: give 1 to %d, and N large enough for %d cells a side\n",
                split, MAX_SPLIT, 2 * split + 1);
        return 1;
    }
    /* the particles' fields, padded by LANES zeros (read, masked, by the cell-blocked loop) */
    real *x = calloc(N + LANES, sizeof(real)), *y = calloc(N + LANES, sizeof(real));
    real *u = calloc(N + LANES, sizeof(real)), *v = calloc(N + LANES, sizeof(real));
    real *ax = calloc(N + LANES, sizeof(real)), *ay = calloc(N + LANES, sizeof(real));
    real *rho = calloc(N + LANES, sizeof(real)), *p = calloc(N + LANES, sizeof(real));
    real *coef = calloc(N + LANES, sizeof(real)), *inv = calloc(N + LANES, sizeof(real));
    real *buf = malloc(sizeof(real) * N * 6);
    int *cid = malloc(sizeof(int) * N), *start = calloc(ncell + 1, sizeof(int));
    int *order = malloc(sizeof(int) * N);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            int a = i * n + j;
            x[a] = (i + 0.5f) * dx;
            y[a] = (j + 0.5f) * dx;
            u[a] = -U * cosf(2 * (real)M_PI * x[a]) * sinf(2 * (real)M_PI * y[a]);
            v[a] = U * sinf(2 * (real)M_PI * x[a]) * cosf(2 * (real)M_PI * y[a]);
        }
    long long pairs_inside = 0, candidates = 0;
    double wall0 = 0, cpu0 = 0;
    for (int s = -1; s < steps; s++) { /* step -1: the first right-hand side, untimed */
        if (s == 0) {
            wall0 = now(CLOCK_MONOTONIC);
            cpu0 = now(CLOCK_PROCESS_CPUTIME_ID);
            pairs_inside = candidates = 0;
        }
        if (s >= 0) { /* kick, drift */
            for (int a = 0; a < N; a++) {
                u[a] += 0.5f * dt * ax[a];
                v[a] += 0.5f * dt * ay[a];
                x[a] += dt * u[a];
                y[a] += dt * v[a];
                x[a] -= floorf(x[a]);
                y[a] -= floorf(y[a]);
            }
        }
        /* cell list: counting sort of the particles by cell, arrays reordered */
        memset(start, 0, sizeof(int) * (ncell + 1));
        for (int a = 0; a < N; a++) {
            int ci = (int)(x[a] / cell), cj = (int)(y[a] / cell);
            ci = ci < nc ? ci : nc - 1;
            cj = cj < nc ? cj : nc - 1;
            cid[a] = ci * nc + cj;
            start[cid[a] + 1]++;
        }
        for (int c = 0; c < ncell; c++) start[c + 1] += start[c];
        for (int a = 0; a < N; a++) order[start[cid[a]]++] = a;
        for (int c = ncell; c > 0; c--) start[c] = start[c - 1];
        start[0] = 0;
        real *fields[6] = {x, y, u, v, ax, ay};
        for (int f = 0; f < 6; f++) {
            for (int k = 0; k < N; k++) buf[f * N + k] = fields[f][order[k]];
            memcpy(fields[f], buf + f * N, sizeof(real) * N);
        }
        long long inside = 0, seen = 0;
        if (mode == 0) {
        /* pass 1: summation density, then the equation of state */
#pragma omp parallel for schedule(static) reduction(+ : inside, seen)
        for (int c = 0; c < ncell; c++) {
            int ci = c / nc, cj = c % nc;
            for (int a = start[c]; a < start[c + 1]; a++) {
                real sum = 0;
                for (int di = -split; di <= split; di++)
                    for (int dj = -split; dj <= split; dj++) {
                        int d = ((ci + di + nc) % nc) * nc + (cj + dj + nc) % nc;
                        for (int b = start[d]; b < start[d + 1]; b++) {
                            real rx = wrap(x[a] - x[b]), ry = wrap(y[a] - y[b]);
                            real r2 = rx * rx + ry * ry;
                            seen++;
                            if (r2 >= support2) continue;
                            sum += shape(sqrtf(r2) / h);
                            inside++;
                        }
                    }
                rho[a] = m * sigma * sum;
                p[a] = c0 * c0 * (rho[a] - rho0);
                coef[a] = p[a] / (rho[a] * rho[a]);
                inv[a] = 1 / rho[a];
            }
        }
        /* pass 2: pressure and Morris viscosity */
#pragma omp parallel for schedule(static)
        for (int c = 0; c < ncell; c++) {
            int ci = c / nc, cj = c % nc;
            for (int a = start[c]; a < start[c + 1]; a++) {
                real fa = coef[a], ia = inv[a], gx = 0, gy = 0;
                for (int di = -split; di <= split; di++)
                    for (int dj = -split; dj <= split; dj++) {
                        int d = ((ci + di + nc) % nc) * nc + (cj + dj + nc) % nc;
                        for (int b = start[d]; b < start[d + 1]; b++) {
                            real rx = wrap(x[a] - x[b]), ry = wrap(y[a] - y[b]);
                            real r2 = rx * rx + ry * ry;
                            if (r2 >= support2) continue;
                            real r = sqrtf(r2), dw = shape_derivative(r / h);
                            real f = r > 0 ? sigma / h * dw / r : 0; /* grad W = f (r_a - r_b) */
                            real pres = -m * (fa + coef[b]);
                            real visc = m * nu * (ia + inv[b]) * (r2 * f) / (r2 + eta2);
                            gx += pres * f * rx + visc * (u[a] - u[b]);
                            gy += pres * f * ry + visc * (v[a] - v[b]);
                        }
                    }
                ax[a] = gx;
                ay[a] = gy;
            }
        }
        } else if (mode == 1) {
        /* each pair once (b after a in the cell's order, or in a cell of the upper half
         * of the stencil), its terms added to both particles: one thread */
        for (int a = 0; a < N; a++) rho[a] = 0;
        for (int c = 0; c < ncell; c++) {
            int ci = c / nc, cj = c % nc;
            for (int di = 0; di <= split; di++)
                for (int dj = -split; dj <= split; dj++) {
                    if (di == 0 && dj < 0) continue;
                    int d = ((ci + di + nc) % nc) * nc + (cj + dj + nc) % nc;
                    for (int a = start[c]; a < start[c + 1]; a++) {
                        real sum = 0;
                        for (int b = d == c ? a + 1 : start[d]; b < start[d + 1]; b++) {
                            real rx = wrap(x[a] - x[b]), ry = wrap(y[a] - y[b]);
                            real r2 = rx * rx + ry * ry;
                            seen++;
                            if (r2 >= support2) continue;
                            real w = shape(sqrtf(r2) / h);
                            sum += w;
                            rho[b] += w;
                            inside += 2;
                        }
                        rho[a] += sum;
                    }
                }
        }
        for (int a = 0; a < N; a++) { /* the self term, then the equation of state */
            rho[a] = m * sigma * (rho[a] + shape(0)); /* the self term */
            p[a] = c0 * c0 * (rho[a] - rho0);
            coef[a] = p[a] / (rho[a] * rho[a]);
            inv[a] = 1 / rho[a];
            ax[a] = ay[a] = 0;
        }
        for (int c = 0; c < ncell; c++) {
            int ci = c / nc, cj = c % nc;
            for (int di = 0; di <= split; di++)
                for (int dj = -split; dj <= split; dj++) {
                    if (di == 0 && dj < 0) continue;
                    int d = ((ci + di + nc) % nc) * nc + (cj + dj + nc) % nc;
                    for (int a = start[c]; a < start[c + 1]; a++) {
                        real fa = coef[a], ia = inv[a], gx = 0, gy = 0;
                        for (int b = d == c ? a + 1 : start[d]; b < start[d + 1]; b++) {
                            real rx = wrap(x[a] - x[b]), ry = wrap(y[a] - y[b]);
                            real r2 = rx * rx + ry * ry;
                            if (r2 >= support2) continue;
                            real r = sqrtf(r2), dw = shape_derivative(r / h);
                            real f = r > 0 ? sigma / h * dw / r : 0;
                            real pres = -m * (fa + coef[b]);
                            real visc = m * nu * (ia + inv[b]) * (r2 * f) / (r2 + eta2);
                            real fx = pres * f * rx + visc * (u[a] - u[b]);
                            real fy = pres * f * ry + visc * (v[a] - v[b]);
                            gx += fx;
                            gy += fy;
                            ax[b] -= fx; /* equal masses: m_b a_b = -m_a a_a for the pair */
                            ay[b] -= fy;
                        }
                        ax[a] += gx;
                        ay[a] += gy;
                    }
                }
        }
        } else {
        /* cell-blocked: each pair once over contiguous runs of cells (kernel_sum_rows,
         * momentum_sum_rows), threads over stripes of rows (over_stripes) */
        Fluid fluid = {nc, split, mode == 3, start, x, y, u, v, coef, inv, rho, ax, ay,
                       h, support2, sigma, m, nu, eta2};
        for (int a = 0; a < N; a++) rho[a] = 0;
        long long counts[2] = {0, 0};
        over_stripes(&fluid, kernel_sum_rows, counts);
        inside = 2 * counts[0];
        seen = counts[1];
        for (int a = 0; a < N; a++) { /* the self term, then the equation of state */
            rho[a] = m * sigma * (rho[a] + shape(0));
            p[a] = c0 * c0 * (rho[a] - rho0);
            coef[a] = p[a] / (rho[a] * rho[a]);
            inv[a] = 1 / rho[a];
            ax[a] = ay[a] = 0;
        }
        over_stripes(&fluid, momentum_sum_rows, counts);
        }
        if (s >= 0) {
            pairs_inside += inside;
            candidates += seen;
            for (int a = 0; a < N; a++) { /* kick */
                u[a] += 0.5f * dt * ax[a];
                v[a] += 0.5f * dt * ay[a];
            }
        }
    }
    double wall = now(CLOCK_MONOTONIC) - wall0, cpu = now(CLOCK_PROCESS_CPUTIME_ID) - cpu0;
    double ke = 0;
    for (int a = 0; a < N; a++) ke += 0.5 * m * (u[a] * u[a] + v[a] * v[a]);
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    printf("particles=%d steps=%d threads=%d wall_ms_per_step=%.3f cpu_ms_per_step=%.3f "
           "neighbours_inside=%.1f candidates=%.1f kinetic_energy=%.6e\n",
           N, steps, threads, 1e3 * wall / steps, 1e3 * cpu / steps,
           (double)pairs_inside / steps / N, (double)candidates / steps / N, ke);
    return 0;
}
