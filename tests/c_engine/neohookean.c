/* A NeoHookean engine in plain C99, written from docs/conventions.md only.
 *
 *   cc -O2 -o neohookean neohookean.c -lm
 *   ./neohookean INPUT_DIR OUTPUT_DIR
 *
 * Reads case.txt and the raw little-endian arrays of INPUT_DIR, writes force.f64, the stiffness
 * as COO triplets (element matrices, duplicates summed by the reader) and energy.f64.
 * W = mu/2 (I1 - 3) - mu ln J + lam/2 (ln J)^2;  f = -dPi/dx;  K = d2Pi/dx2;  dof = 3*node + c.
 * Compiled with -DMISTAKE it returns +dPi/dx instead of the force (a sign mistake to be caught).
 * Compiled with -DSINGLE it computes in float (as GPU and real-time engines do) and writes its
 * values as float32 (force.f32, stiffness_values.f32, energy.f32).
 * Compiled with -DUPPER it writes only the upper triangle of K (a storage mistake).
 */
#include <errno.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#ifdef SINGLE
typedef float real;
#define EXT ".f32"
#define LOG logf
#else
typedef double real;
#define EXT ".f64"
#define LOG log
#endif

static void die(const char *msg, const char *arg) {
    fprintf(stderr, "neohookean: %s%s\n", msg, arg ? arg : "");
    exit(2);
}

static void *read_raw(const char *dir, const char *name, size_t count, size_t size) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *fp = fopen(path, "rb");
    if (!fp) die("cannot open ", path);
    void *buf = malloc(count * size);
    if (!buf || fread(buf, size, count, fp) != count) die("short read: ", path);
    fclose(fp);
    return buf;
}

static void write_raw(const char *dir, const char *name, const void *buf, size_t count, size_t size) {
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", dir, name);
    FILE *fp = fopen(path, "wb");
    if (!fp || fwrite(buf, size, count, fp) != count) die("cannot write ", path);
    fclose(fp);
}

static real det3(const real A[3][3]) {
    return A[0][0] * (A[1][1] * A[2][2] - A[1][2] * A[2][1]) - A[0][1] * (A[1][0] * A[2][2] - A[1][2] * A[2][0])
         + A[0][2] * (A[1][0] * A[2][1] - A[1][1] * A[2][0]);
}

static void inv3(const real A[3][3], real B[3][3]) {
    real d = det3(A);
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 3; j++) {
            int i1 = (j + 1) % 3, i2 = (j + 2) % 3, j1 = (i + 1) % 3, j2 = (i + 2) % 3;
            B[i][j] = (A[i1][j1] * A[i2][j2] - A[i1][j2] * A[i2][j1]) / d; /* cofactor transpose */
        }
}

int main(int argc, char **argv) {
    if (argc != 3) die("usage: neohookean INPUT_DIR OUTPUT_DIR", NULL);
    const uint16_t probe = 1;
    if (*(const uint8_t *)&probe != 1) die("this engine assumes a little-endian machine", NULL);
    const char *in = argv[1], *out = argv[2];

    /* case.txt: one "key value..." per line */
    char path[4096], line[8192], name[256] = "";
    long n = -1, m = -1;
    double mu = NAN, lam = NAN;
    snprintf(path, sizeof path, "%s/case.txt", in);
    FILE *fp = fopen(path, "r");
    if (!fp) die("cannot open ", path);
    while (fgets(line, sizeof line, fp)) {
        char pname[64];
        double v;
        if (sscanf(line, "n_nodes %ld", &n) == 1 || sscanf(line, "n_cells %ld", &m) == 1) continue;
        if (sscanf(line, "name %255s", name) == 1) continue;
        if (sscanf(line, "parameter %63s %lf", pname, &v) == 2) {
            if (!strcmp(pname, "mu")) mu = v;
            if (!strcmp(pname, "lam")) lam = v;
        }
    }
    fclose(fp);
    if (strcmp(name, "NeoHookean")) die("only NeoHookean is implemented, not ", name);
    if (n <= 0 || m <= 0 || isnan(mu) || isnan(lam)) die("case.txt lacks n_nodes, n_cells, mu or lam", NULL);

    double *X64 = read_raw(in, "points.f64", 3 * n, 8);
    double *x64 = read_raw(in, "positions.f64", 3 * n, 8);
    real *X = malloc(3 * n * sizeof(real)), *x = malloc(3 * n * sizeof(real));
    for (long k = 0; k < 3 * n; k++) { X[k] = (real)X64[k]; x[k] = (real)x64[k]; }
    int64_t *cells = read_raw(in, "cells.i64", 4 * m, 8);
    real *f = calloc(3 * n, sizeof(real));
    int64_t *rows = malloc(144 * m * sizeof(int64_t)), *cols = malloc(144 * m * sizeof(int64_t));
    real *vals = malloc(144 * m * sizeof(real));
    real energy = 0.0, rmu = (real)mu, rlam = (real)lam;

    long e = 0; /* entries written so far */
    for (long c = 0; c < m; c++) {
        const int64_t *v = cells + 4 * c;
        real E[3][3], Einv[3][3], D[4][3], F[3][3] = {{0}}, Fi[3][3], FiT[3][3];
        for (int i = 0; i < 3; i++)
            for (int k = 0; k < 3; k++) E[k][i] = X[3 * v[i + 1] + k] - X[3 * v[0] + k]; /* columns X_a - X_0 */
        real V0 = det3(E) / (real)6;
        inv3(E, Einv);
        for (int k = 0; k < 3; k++) {
            D[0][k] = 0.0;
            for (int a = 1; a < 4; a++) {
                D[a][k] = Einv[a - 1][k]; /* rows of the inverse */
                D[0][k] -= D[a][k];
            }
        }
        for (int a = 0; a < 4; a++) /* F = sum_a x_a (x) D_a */
            for (int k = 0; k < 3; k++)
                for (int i = 0; i < 3; i++) F[k][i] += x[3 * v[a] + k] * D[a][i];
        real J = det3(F), lnJ = LOG(J), I1 = 0.0;
        inv3(F, Fi);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) {
                FiT[i][j] = Fi[j][i];
                I1 += F[i][j] * F[i][j];
            }
        energy += V0 * ((real)0.5 * rmu * (I1 - (real)3) - rmu * lnJ + (real)0.5 * rlam * lnJ * lnJ);
        real P[3][3]; /* first Piola-Kirchhoff: rmu F + (rlam ln J - rmu) F^-T */
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 3; j++) P[i][j] = rmu * F[i][j] + (rlam * lnJ - rmu) * FiT[i][j];
        for (int a = 0; a < 4; a++)
            for (int i = 0; i < 3; i++) {
                real g = 0.0; /* dPi/dx_a,i = V0 sum_I P_iI D_a,I */
                for (int I = 0; I < 3; I++) g += P[i][I] * D[a][I];
#ifdef MISTAKE
                f[3 * v[a] + i] += V0 * g;
#else
                f[3 * v[a] + i] -= V0 * g;
#endif
            }
        /* dP_iI/dF_jJ = rmu d_ij d_IJ + rlam FiT_iI FiT_jJ - (rlam ln J - rmu) FiT_iJ FiT_jI */
        for (int a = 0; a < 4; a++)
            for (int i = 0; i < 3; i++)
                for (int b = 0; b < 4; b++)
                    for (int j = 0; j < 3; j++) {
                        real s = 0.0;
                        for (int I = 0; I < 3; I++)
                            for (int Jj = 0; Jj < 3; Jj++) {
                                real A = rlam * FiT[i][I] * FiT[j][Jj]
                                         - (rlam * lnJ - rmu) * FiT[i][Jj] * FiT[j][I];
                                if (i == j && I == Jj) A += rmu;
                                s += D[a][I] * A * D[b][Jj];
                            }
#ifdef UPPER
                        if (3 * v[a] + i > 3 * v[b] + j) continue; /* the mistake: upper triangle only */
#endif
                        rows[e] = 3 * v[a] + i;
                        cols[e] = 3 * v[b] + j;
                        vals[e] = V0 * s;
                        e++;
                    }
    }
    if (mkdir(out, 0755) != 0 && errno != EEXIST) die("cannot create ", out);
    long nnz = e;
    write_raw(out, "force" EXT, f, 3 * n, sizeof(real));
    write_raw(out, "stiffness_rows.i64", rows, nnz, 8);
    write_raw(out, "stiffness_cols.i64", cols, nnz, 8);
    write_raw(out, "stiffness_values" EXT, vals, nnz, sizeof(real));
    write_raw(out, "energy" EXT, &energy, 1, sizeof(real));
    return 0;
}
