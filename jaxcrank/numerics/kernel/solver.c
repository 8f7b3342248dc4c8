/* The adaptive Tsitouras 5(4) loop of one trajectory, as diffrax 0.7 steps it with
 * PIDController(pcoeff=0, icoeff=1, norm=rms_norm) and throw=False, plus the headline
 * metrics of jaxcrank.numerics.tracking.MetricsTracking. Included after the
 * generated constants (NP, NY, NPEAK, NRMS, TAB_*, controller constants) and the
 * generated functions jk_field, jk_frame, jk_interp. Valid C99 and CUDA C++. */

#define JK_OK 0
#define JK_MAX_STEPS 1

KFN double jk_sample_time(long i, long n, double last) {
  /* MetricsTracking.sample_time with first_sample = 0 */
  double step = (last - 0.0) / (double)(n - 1);
  return i >= n - 1 ? last : 0.0 + (double)i * step;
}

KFN int jk_solve_one(const double *KRESTRICT p, double T1, double t_start, long n_samples, long max_steps,
                     double rtol, double atol, double dt0, double *KRESTRICT y, double *KRESTRICT peaks,
                     double *KRESTRICT whole, double *KRESTRICT sums, long *KRESTRICT count,
                     long *KRESTRICT accepted, long *KRESTRICT rejected) {
  double f0[NY], f7[NY], k[7 * NY], ys[NY], rate[NY], pk[NPEAK], rs[NRMS], yi[NY];
  const double T0 = 0.0;
  double floor_ = T1;
  for (int i = 0; i < 100; i++) floor_ = nextafter(floor_, -KINF);
  for (int j = 0; j < NPEAK; j++) peaks[j] = whole[j] = PEAK_INIT[j];
  for (int j = 0; j < NRMS; j++) sums[j] = 0.0;
  long cnt = 0, next_sample = 0, steps = 0, acc = 0, rej = 0;
  jk_field(p, T0, y, f0);
  double tprev = T0, tnext = kmin(T0 + dt0, T1);
  while (tprev < T1 && steps < max_steps) {
    const double t0 = tprev, t1 = tnext, dt = t1 - t0;
    for (int i = 0; i < NY; i++) k[i] = f0[i] * dt;
    for (int s = 1; s < 7; s++) {
      for (int i = 0; i < NY; i++) {
        double inc = 0.0;
        for (int j = 0; j < s; j++) inc += TAB_A[7 * s + j] * k[NY * j + i];
        ys[i] = y[i] + inc;
      }
      const double ts = TAB_C[s] == 1.0 ? t1 : t0 + TAB_C[s] * dt;
      if (s < 6) {
        jk_field(p, ts, ys, rate);
        for (int i = 0; i < NY; i++) k[NY * s + i] = rate[i] * dt;
      } else { /* stage 7 = (t1, y1): the FSAL rate and the step-end signals */
        jk_frame(p, ts, ys, f7, pk, rs);
        for (int i = 0; i < NY; i++) k[NY * s + i] = f7[i] * dt;
      }
    }
    /* error estimate and its scaled RMS norm (NaN errors count as infinite) */
    int nan1 = 0;
    for (int i = 0; i < NY; i++) nan1 |= ys[i] != ys[i];
    double ss = 0.0;
    for (int i = 0; i < NY; i++) {
      double e = 0.0;
      for (int j = 0; j < 7; j++) e += TAB_B_ERR[j] * k[NY * j + i];
      if (e != e) e = KINF;
      const double y1c = nan1 ? y[i] : ys[i];
      const double mag = kmax(fabs(y[i]), fabs(y1c));
      const double sc = e / (atol + mag * rtol);
      ss += sc * sc;
    }
    const double scaled = sqrt(ss) / NORM_SQRT_N;
    const int keep = scaled < 1.0;
    const double inv = 1.0 / scaled;
    const double fmin_ = keep ? 1.0 : FACTOR_MIN;
    const double fmax_ = keep ? FACTOR_MAX : SAFETY;
    const double factor = kmin(kmax(SAFETY * pow(inv, ERROR_EXPONENT), fmin_), fmax_);
    const double dt_next = dt * factor;
    const double next_t0 = keep ? t1 : t0;
    const double next_t1 = next_t0 + dt_next;
    tprev = kmin(next_t0, T1);
    tnext = next_t1 > floor_ ? (keep ? T1 : tprev + 0.5 * (T1 - tprev)) : next_t1;
    if (keep) {
      const int in_window = t1 > t_start;
      for (int j = 0; j < NPEAK; j++) {
        if (in_window) peaks[j] = kmax(peaks[j], pk[j]);
        whole[j] = kmax(whole[j], pk[j]);
      }
      while (next_sample < n_samples && jk_sample_time(next_sample, n_samples, T1) <= t1) {
        const double tsmp = jk_sample_time(next_sample, n_samples, T1);
        jk_interp(t0, t1, y, k, tsmp, yi);
        jk_frame(p, tsmp, yi, rate, pk, rs);
        if (tsmp > t_start) {
          for (int j = 0; j < NRMS; j++) sums[j] += rs[j] * rs[j];
          cnt += 1;
        }
        next_sample += 1;
      }
      for (int i = 0; i < NY; i++) {
        y[i] = ys[i];
        f0[i] = f7[i];
      }
      acc += 1;
    } else {
      rej += 1;
    }
    steps += 1;
  }
  *count = cnt;
  *accepted = acc;
  *rejected = rej;
  return tprev < T1 ? JK_MAX_STEPS : JK_OK;
}

#ifndef __CUDACC__
/* CPU entry points (ctypes). Rows are designs; every array is row-major. */

int jk_solve(long n, int threads, const double *params, const double *t_end, const double *t_start, long n_samples,
             long max_steps, double rtol, double atol, double dt0, double *y, double *peaks, double *whole,
             double *sums, long *count, long *accepted, long *rejected, int *result) {
  long d;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (d = 0; d < n; d++) {
    result[d] = jk_solve_one(params + NP * d, t_end[d], t_start[d], n_samples, max_steps, rtol, atol, dt0,
                             y + NY * d, peaks + NPEAK * d, whole + NPEAK * d, sums + NRMS * d, count + d,
                             accepted + d, rejected + d);
  }
  return 0;
}

int jk_layout(long *out) {
  out[0] = NP;
  out[1] = NY;
  out[2] = NPEAK;
  out[3] = NRMS;
  return 0;
}

int jk_frame_batch(long n, const double *params, const double *t, const double *y, double *rate, double *peak,
                   double *rms) {
  for (long d = 0; d < n; d++) jk_frame(params + NP * d, t[d], y + NY * d, rate + NY * d, peak + NPEAK * d,
                                        rms + NRMS * d);
  return 0;
}

#else
extern "C" __global__ void jk_solve_gpu(long n, const double *params, const double *t_end, const double *t_start,
                                        long n_samples, long max_steps, double rtol, double atol, double dt0,
                                        double *y, double *peaks, double *whole, double *sums, long *count,
                                        long *accepted, long *rejected, int *result) {
  long d = (long)blockIdx.x * blockDim.x + threadIdx.x;
  if (d >= n) return;
  result[d] = jk_solve_one(params + NP * d, t_end[d], t_start[d], n_samples, max_steps, rtol, atol, dt0,
                           y + NY * d, peaks + NPEAK * d, whole + NPEAK * d, sums + NRMS * d, count + d,
                           accepted + d, rejected + d);
}
#endif

#ifndef __CUDACC__
/* The same loop on W designs at once, one per vector lane (jk_field_v, jk_frame_v: the
 * generated functions on GCC vectors). Each lane keeps its own times, steps and
 * accumulators; a lane that has finished idles (its updates are masked) until the
 * group's last lane finishes. A lane's arithmetic is the scalar loop's, operation for
 * operation, so its numbers equal jk_solve_one's bit for bit. */
static void jk_solve_group(int lanes, const double *params, const double *t_end, const double *t_start,
                           long n_samples, long max_steps, double rtol, double atol, double dt0, double *y_out,
                           double *peaks_out, double *whole_out, double *sums_out, long *count_out,
                           long *accepted_out, long *rejected_out, int *result_out) {
  vd p[NP > 0 ? NP : 1], y[NY], f0[NY], f7[NY], k[7][NY], ys[NY], rate[NY], pk[NPEAK], rs[NRMS];
  vd peaks[NPEAK], whole[NPEAK];
  double sums[W][NRMS];
  long cnt[W], next_sample[W], steps[W], acc[W], rej[W];
  vd T1, tstart, floor_, tprev, tnext;
  for (int l = 0; l < W; l++) {
    const int d = l < lanes ? l : 0; /* unused lanes repeat lane 0 and are dropped */
    for (int i = 0; i < NP; i++) p[i][l] = params[NP * d + i];
    for (int i = 0; i < NY; i++) y[i][l] = y_out[NY * d + i];
    T1[l] = l < lanes ? t_end[d] : 0.0; /* an unused lane is finished from the start */
    tstart[l] = t_start[d];
    double fl = T1[l];
    for (int i = 0; i < 100; i++) fl = nextafter(fl, -KINF);
    floor_[l] = fl;
    cnt[l] = next_sample[l] = steps[l] = acc[l] = rej[l] = 0;
    for (int j = 0; j < NRMS; j++) sums[l][j] = 0.0;
  }
  for (int j = 0; j < NPEAK; j++) peaks[j] = whole[j] = KV(PEAK_INIT[j]);
  const vd zero = KV(0.0);
  jk_field_v(p, zero, y, f0);
  tprev = zero;
  tnext = kv_min(KV(dt0), T1);
  for (;;) {
    vl active = tprev < T1;
    int any = 0;
    for (int l = 0; l < W; l++) {
      if (steps[l] >= max_steps) active[l] = 0;
      any |= active[l] != 0;
    }
    if (!any) break;
    const vd t0 = tprev, t1 = tnext, dt = t1 - t0;
    for (int i = 0; i < NY; i++) k[0][i] = f0[i] * dt;
    for (int s = 1; s < 7; s++) {
      for (int i = 0; i < NY; i++) {
        vd inc = zero;
        for (int j = 0; j < s; j++) inc += TAB_A[7 * s + j] * k[j][i];
        ys[i] = y[i] + inc;
      }
      const vd ts = TAB_C[s] == 1.0 ? t1 : t0 + TAB_C[s] * dt;
      if (s < 6) {
        jk_field_v(p, ts, ys, rate);
        for (int i = 0; i < NY; i++) k[s][i] = rate[i] * dt;
      } else {
        jk_frame_v(p, ts, ys, f7, pk, rs);
        for (int i = 0; i < NY; i++) k[s][i] = f7[i] * dt;
      }
    }
    vl nan1 = KVLZ;
    for (int i = 0; i < NY; i++) nan1 |= ys[i] != ys[i];
    vd ss = zero;
    for (int i = 0; i < NY; i++) {
      vd e = zero;
      for (int j = 0; j < 7; j++) e += TAB_B_ERR[j] * k[j][i];
      e = kv_sel(e != e, KV(KINF), e);
      const vd y1c = kv_sel(nan1, y[i], ys[i]);
      vd ay = y[i], a1 = y1c;
      for (int l = 0; l < W; l++) {
        ay[l] = fabs(ay[l]);
        a1[l] = fabs(a1[l]);
      }
      const vd mag = kv_max(ay, a1);
      const vd sc = e / (atol + mag * rtol);
      ss += sc * sc;
    }
    vd scaled = ss, powed;
    for (int l = 0; l < W; l++) scaled[l] = sqrt(ss[l]) / NORM_SQRT_N;
    const vl keep = (scaled < 1.0) & active;
    const vd inv = 1.0 / scaled;
    for (int l = 0; l < W; l++) powed[l] = pow(inv[l], ERROR_EXPONENT);
    const vd fmin_ = kv_sel(keep, KV(1.0), KV(FACTOR_MIN));
    const vd fmax_ = kv_sel(keep, KV(FACTOR_MAX), KV(SAFETY));
    const vd factor = kv_min(kv_max(SAFETY * powed, fmin_), fmax_);
    const vd next_t0 = kv_sel(keep, t1, t0);
    const vd next_t1 = next_t0 + dt * factor;
    const vd tprev_new = kv_min(next_t0, T1);
    const vd tnext_new = kv_sel(next_t1 > floor_, kv_sel(keep, T1, tprev_new + 0.5 * (T1 - tprev_new)), next_t1);
    tprev = kv_sel(active, tprev_new, tprev);
    tnext = kv_sel(active, tnext_new, tnext);
    const vl in_window = keep & (t1 > tstart);
    for (int j = 0; j < NPEAK; j++) {
      peaks[j] = kv_sel(in_window, kv_max(peaks[j], pk[j]), peaks[j]);
      whole[j] = kv_sel(keep, kv_max(whole[j], pk[j]), whole[j]);
    }
    for (int l = 0; l < W; l++) {
      if (!active[l]) continue;
      steps[l] += 1;
      if (!keep[l]) {
        rej[l] += 1;
        continue;
      }
      acc[l] += 1;
      double y0l[NY], kl[7 * NY], yi[NY], rl[NY], pkl[NPEAK], rsl[NRMS], pl[NP > 0 ? NP : 1];
      int loaded = 0;
      while (next_sample[l] < n_samples && jk_sample_time(next_sample[l], n_samples, T1[l]) <= t1[l]) {
        if (!loaded) {
          for (int i = 0; i < NY; i++) y0l[i] = y[i][l];
          for (int j = 0; j < 7; j++)
            for (int i = 0; i < NY; i++) kl[NY * j + i] = k[j][i][l];
          for (int i = 0; i < NP; i++) pl[i] = p[i][l];
          loaded = 1;
        }
        const double tsmp = jk_sample_time(next_sample[l], n_samples, T1[l]);
        jk_interp(t0[l], t1[l], y0l, kl, tsmp, yi);
        jk_frame(pl, tsmp, yi, rl, pkl, rsl);
        if (tsmp > tstart[l]) {
          for (int j = 0; j < NRMS; j++) sums[l][j] += rsl[j] * rsl[j];
          cnt[l] += 1;
        }
        next_sample[l] += 1;
      }
    }
    for (int i = 0; i < NY; i++) {
      y[i] = kv_sel(keep, ys[i], y[i]);
      f0[i] = kv_sel(keep, f7[i], f0[i]);
    }
  }
  for (int l = 0; l < lanes; l++) {
    for (int i = 0; i < NY; i++) y_out[NY * l + i] = y[i][l];
    for (int j = 0; j < NPEAK; j++) {
      peaks_out[NPEAK * l + j] = peaks[j][l];
      whole_out[NPEAK * l + j] = whole[j][l];
    }
    for (int j = 0; j < NRMS; j++) sums_out[NRMS * l + j] = sums[l][j];
    count_out[l] = cnt[l];
    accepted_out[l] = acc[l];
    rejected_out[l] = rej[l];
    result_out[l] = tprev[l] < T1[l] ? JK_MAX_STEPS : JK_OK;
  }
}

int jk_solve_v(long n, int threads, const double *params, const double *t_end, const double *t_start,
               long n_samples, long max_steps, double rtol, double atol, double dt0, double *y, double *peaks,
               double *whole, double *sums, long *count, long *accepted, long *rejected, int *result) {
  long g, groups = (n + W - 1) / W;
#pragma omp parallel for schedule(dynamic, 1) num_threads(threads)
  for (g = 0; g < groups; g++) {
    const long d = g * W;
    const int lanes = n - d < W ? (int)(n - d) : W;
    jk_solve_group(lanes, params + NP * d, t_end + d, t_start + d, n_samples, max_steps, rtol, atol, dt0,
                   y + NY * d, peaks + NPEAK * d, whole + NPEAK * d, sums + NRMS * d, count + d, accepted + d,
                   rejected + d, result + d);
  }
  return 0;
}
#endif
