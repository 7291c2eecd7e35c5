/* What a fused pair loop costs on this CPU: the step of benchmarks/throughput.py's
 * Taylor-Green (periodic unit square, n x n particles, quintic spline, h = dx, support 3 h,
 * summation density, linear equation of state, Morris viscosity (mu = rho nu), kick-drift-kick with one
 * right-hand side per step), written as plain loops over a cell list rebuilt every step.
 * Not part of sphjax: a ceiling to set the XLA step against (benchmarks/pair_loop_ceiling.py
 * compiles and runs it).  float32, particles re-sorted by cell every step, each pair visited
 * from both sides (no symmetry), OpenMP over particles.
 *
 *   usage: pair_loop_ceiling N STEPS [SPLIT [HALF]]: cells per support
 *   length (default 1); HALF 1: each pair visited once, one thread (default 0)  ->  prints one line of key=value figures
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

/* quintic spline f(q) = (3-q)^5 - 6 (2-q)^5 + 15 (1-q)^5 (each term where positive) */
static inline real shape(real q) {
    real q3 = fmaxf(3 - q, 0), q2 = fmaxf(2 - q, 0), q1 = fmaxf(1 - q, 0);
    real q3_2 = q3 * q3, q2_2 = q2 * q2, q1_2 = q1 * q1;
    return q3_2 * q3_2 * q3 - 6 * q2_2 * q2_2 * q2 + 15 * q1_2 * q1_2 * q1;
}

/* its derivative f'(q) */
static inline real shape_derivative(real q) {
    real q3 = fmaxf(3 - q, 0), q2 = fmaxf(2 - q, 0), q1 = fmaxf(1 - q, 0);
    return -5 * q3 * q3 * q3 * q3 + 30 * q2 * q2 * q2 * q2 - 75 * q1 * q1 * q1 * q1;
}

int main(int argc, char **argv) {
    int n = argc > 1 ? atoi(argv[1]) : 200, steps = argc > 2 ? atoi(argv[2]) : 50;
    int N = n * n;
    real dx = 1.0f / n, h = dx, support = 3.0f * h, U = 1.0f, c0 = 10.0f * U, rho0 = 1.0f;
    real nu = 0.01f, m = rho0 * dx * dx, dt = 0.25f * h / (c0 + U);
    real support2 = support * support;
    real sigma = 7.0f / (478.0f * (real)M_PI * h * h), eta2 = 0.01f * h * h;
    int half = argc > 4 ? atoi(argv[4]) : 0; /* 1: each pair once */
    int split = argc > 3 ? atoi(argv[3]) : 1; /* cells per support length */
    int nc = (int)floorf(split / support); /* cells per side, each at least support / split */
    real cell = 1.0f / nc;
    int ncell = nc * nc;
    real *x = malloc(sizeof(real) * N), *y = malloc(sizeof(real) * N);
    real *u = malloc(sizeof(real) * N), *v = malloc(sizeof(real) * N);
    real *ax = calloc(N, sizeof(real)), *ay = calloc(N, sizeof(real));
    real *rho = malloc(sizeof(real) * N), *p = malloc(sizeof(real) * N);
    real *coef = malloc(sizeof(real) * N), *inv = malloc(sizeof(real) * N);
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
        if (!half) {
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
        } else {
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
