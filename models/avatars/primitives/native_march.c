/* The primitives' hot loops for native.py: display's march (march_rays, no gradients) and training's trilinear
   lookups with their gradients (lookup_forward, lookup_backward).

   The march is models/avatars/primitives/march.py's display march, one ray at a time.

   Each ray takes its candidate primitives in their list's order (front to back), meets each box by the slab test
   in the box's unit frame, takes one sample a voxel spacing it crosses and one more (2 at least, `most` at most)
   at the midpoints of equal steps, looks the density up trilinearly (voxel centres at -1 + 2k/(M-1), clamped to
   the grid, as grid_sample's align_corners and border padding do), composites front to back (w = T (1 - exp(-tau)),
   tau = sigma delta clamped to [0, 30], the light left multiplied down sample by sample), looks the colour
   channels up only where w reaches min_weight, and stops once no more than stop_below of its light gets through
   (checked before each candidate, where the torch march checks between waves of them). The torch march
   (march.py) is the reference: tests hold the two to each other's images.

   Built by native.py with the system's C compiler; called through ctypes, which lets go of Python's lock, so
   that two threads each march their own rays at once. */

#include <math.h>
#include <stdint.h>

static inline float clampf(float x, float lo, float hi) { return x < lo ? lo : (x > hi ? hi : x); }

/* The offset of the first corner of the cell holding local (3) in an M^3 grid [z][y][x], and the fractions f of
   the way across the cell along x, y and z. */
static inline void corner(const float local[3], int M, int64_t *base, float f[3]) {
    int64_t idx[3];
    for (int a = 0; a < 3; a++) {
        float g = clampf((local[a] + 1.0f) * 0.5f * (float)(M - 1), 0.0f, (float)(M - 1));
        int64_t i0 = M > 1 ? (int64_t)floorf(g) : 0;
        if (M > 1 && i0 > M - 2) i0 = M - 2;
        idx[a] = i0;
        f[a] = M > 1 ? g - (float)i0 : 0.0f;
    }
    *base = (idx[2] * M + idx[1]) * M + idx[0];
}

/* The eight corners of the cell at base (their offsets in an M^3 grid) and their trilinear weights. */
static inline void cell(int M, int64_t base, const float f[3], int64_t offset[8], float weight[8]) {
    if (M == 1) {
        for (int k = 0; k < 8; k++) offset[k] = base, weight[k] = k == 0 ? 1.0f : 0.0f;
        return;
    }
    for (int k = 0; k < 8; k++) {
        int dx = k & 1, dy = (k >> 1) & 1, dz = k >> 2;
        offset[k] = base + ((int64_t)dz * M + dy) * M + dx;
        weight[k] = (dx ? f[0] : 1.0f - f[0]) * (dy ? f[1] : 1.0f - f[1]) * (dz ? f[2] : 1.0f - f[2]);
    }
}

/* values: each primitive's grid [z][y][x] of its density then its C colour channels, side by side (a sample's
   density and colour share cache lines). Marches rays[0..n) (indices into the R rays) and writes their rows of
   out (R x C: the colour channels over the background, rgb first), opacity and depth (R). stats: lookups and
   segments made, added to. */
void march_rays(int64_t n, const int64_t *rays, const float *origins, const float *directions,
                const float *background, int background_per_ray,
                int64_t P, int M, int C, const float *centres, const float *to_box, const float *values,
                const int64_t *list_prims, const int64_t *start, const int64_t *count,
                int most, float stop_below, float min_weight,
                float *out, float *opacity, float *depth, int64_t *stats) {
    const int64_t cells = (int64_t)M * M * M;
    const int least = most < 2 ? most : 2;
    float acc[64];
    int64_t lookups = 0, segments = 0;
    for (int64_t i = 0; i < n; i++) {
        const int64_t r = rays[i];
        const float *o = origins + 3 * r, *d = directions + 3 * r;
        for (int c = 0; c < C; c++) acc[c] = 0.0f;
        double sum_w = 0.0, sum_wt = 0.0;
        float T = 1.0f;
        for (int64_t k = 0; k < count[r]; k++) {
            if (stop_below > 0.0f && T <= stop_below) break;
            const int64_t p = list_prims[start[r] + k];
            if (p < 0 || p >= P) continue;
            const float *m = to_box + 9 * p, *cp = centres + 3 * p;
            const float v[3] = {o[0] - cp[0], o[1] - cp[1], o[2] - cp[2]};
            float ob[3], db[3], t_in = 0.0f, t_out = INFINITY;
            for (int a = 0; a < 3; a++) {
                ob[a] = m[3 * a] * v[0] + m[3 * a + 1] * v[1] + m[3 * a + 2] * v[2];
                db[a] = m[3 * a] * d[0] + m[3 * a + 1] * d[1] + m[3 * a + 2] * d[2];
                float lo, hi;
                if (fabsf(db[a]) < 1e-9f) {
                    int inside = fabsf(ob[a]) <= 1.0f;
                    lo = inside ? -INFINITY : INFINITY;
                    hi = inside ? INFINITY : -INFINITY;
                } else {
                    float inv = 1.0f / db[a];
                    float ta = (-1.0f - ob[a]) * inv, tb = (1.0f - ob[a]) * inv;
                    lo = ta < tb ? ta : tb;
                    hi = ta < tb ? tb : ta;
                }
                if (lo > t_in) t_in = lo;
                if (hi < t_out) t_out = hi;
            }
            if (!(t_out > t_in)) continue;
            segments++;
            float length = sqrtf(db[0] * db[0] + db[1] * db[1] + db[2] * db[2]);
            float spacings = length * (t_out - t_in) * 0.5f * (float)(M > 1 ? M - 1 : 1);
            float steps_f = ceilf(spacings) + 1.0f;
            int steps = steps_f <= (float)most ? (int)steps_f : most;  /* NaN and inf: most */
            if (steps < least) steps = least;
            float step = (t_out - t_in) / (float)steps;
            const float *grid = values + p * cells * (C + 1);
            for (int s = 0; s < steps; s++) {
                float t = t_in + step * ((float)s + 0.5f);
                float local[3], f[3], sigma;
                int64_t base;
                for (int a = 0; a < 3; a++) local[a] = clampf(ob[a] + db[a] * t, -1.0f, 1.0f);
                int64_t offset[8];
                float weight[8];
                corner(local, M, &base, f);
                cell(M, base, f, offset, weight);
                sigma = 0.0f;
                for (int q = 0; q < 8; q++) sigma += weight[q] * grid[offset[q] * (C + 1)];
                lookups++;
                float tau = clampf(sigma * step, 0.0f, 30.0f);
                if (isnan(tau)) tau = 0.0f;
                float pass = expf(-tau);
                float w = T * (1.0f - pass);
                if (w >= min_weight) {
                    for (int q = 0; q < 8; q++) {
                        const float wq = w * weight[q], *v = grid + offset[q] * (C + 1) + 1;
                        for (int c = 0; c < C; c++) acc[c] += wq * v[c];
                    }
                    lookups++;
                }
                sum_w += w;
                sum_wt += (double)w * t;
                T *= pass;
            }
        }
        const float *bg = background + (background_per_ray ? 3 * r : 0);
        for (int c = 0; c < C; c++) out[r * C + c] = acc[c] + (c < 3 ? T * bg[c] : 0.0f);
        opacity[r] = (float)sum_w;
        depth[r] = sum_w > 1e-10 ? (float)(sum_wt / sum_w) : 0.0f;
    }
    stats[0] += lookups;
    stats[1] += segments;
}

/* Training's lookups: values (P x M^3 x C, [z][y][x][c]) of primitives prim[i] at box coordinates local[i] (3, in
   [-1, 1]: voxel centres at -1 + 2k/(M-1), clamped to the grid as grid_sample's align_corners and border padding
   read them), trilinearly, into out (n x C). */
void lookup_forward(int64_t n, const int64_t *prim, const float *local, const float *values, int M, int C,
                    float *out) {
    const int64_t cells = (int64_t)M * M * M;
    for (int64_t i = 0; i < n; i++) {
        int64_t base, offset[8];
        float f[3], weight[8];
        corner(local + 3 * i, M, &base, f);
        cell(M, base, f, offset, weight);
        const float *grid = values + prim[i] * cells * C;
        float *o = out + i * C;
        for (int c = 0; c < C; c++) o[c] = 0.0f;
        for (int q = 0; q < 8; q++) {
            const float *v = grid + offset[q] * C;
            for (int c = 0; c < C; c++) o[c] += weight[q] * v[c];
        }
    }
}

/* The gradients of lookup_forward: grad_out (n x C) added into grad_values (P x M^3 x C) and written to
   grad_local (n x 3; zero along an axis where the coordinate lies beyond the grid's outer voxel centres, where the
   lookup is clamped). */
void lookup_backward(int64_t n, const int64_t *prim, const float *local, const float *values, int M, int C,
                     const float *grad_out, float *grad_values, float *grad_local) {
    const int64_t cells = (int64_t)M * M * M;
    const float scale = 0.5f * (float)(M > 1 ? M - 1 : 0);
    for (int64_t i = 0; i < n; i++) {
        int64_t base, offset[8];
        float f[3], weight[8];
        const float *x = local + 3 * i;
        corner(x, M, &base, f);
        cell(M, base, f, offset, weight);
        const int64_t g0 = prim[i] * cells * C;
        const float *go = grad_out + i * C;
        float dot[8];
        for (int q = 0; q < 8; q++) {
            float *gv = grad_values + g0 + offset[q] * C;
            const float *v = values + g0 + offset[q] * C;
            dot[q] = 0.0f;
            for (int c = 0; c < C; c++) {
                gv[c] += weight[q] * go[c];
                dot[q] += v[c] * go[c];
            }
        }
        for (int a = 0; a < 3; a++) {
            float g = (x[a] + 1.0f) * scale;
            if (M <= 1 || g < 0.0f || g > (float)(M - 1)) {
                grad_local[3 * i + a] = 0.0f;
                continue;
            }
            float d = 0.0f;
            for (int q = 0; q < 8; q++) {
                int bit[3] = {q & 1, (q >> 1) & 1, q >> 2};
                float dw = bit[a] ? 1.0f : -1.0f;
                for (int b = 0; b < 3; b++)
                    if (b != a) dw *= bit[b] ? f[b] : 1.0f - f[b];
                d += dw * dot[q];
            }
            grad_local[3 * i + a] = d * scale;
        }
    }
}
