// The per-terrain optimal D (Losasso & Hoppe 2004, section 7 footnote): the 8-fold symmetric 11x11
// filter with DC gain 1 minimising ||T - U(D(T))||_2 on sample windows, by least squares.
//
// U and D are linear, so U(D(T)) = sum_k a_k U(D_k(T)) over the 21 orbit basis filters D_k. With the
// DC constraint a_0 = 1 - sum_{k>0} n_k a_k (n_k = orbit size) the problem becomes the unconstrained
// least squares  min || (T - P_0) - sum_{k>0} a_k (P_k - n_k P_0) ||  with P_k = U(D_k(T)).
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "pyramid/internal/filter_downsample.h"
#include "pyramid/pyramid.h"

namespace terrain {
namespace {

constexpr int kOrbits = 21;
constexpr int kUnknowns = kOrbits - 1;
// Samples this close to a window edge see the reflected extension of D and U, not the terrain.
constexpr int64_t kMargin = 8;

std::array<double, kOrbits> default_orbit_weights() {
  std::array<double, kOrbits> w{};
  w[0] = 0.25, w[1] = 0.125, w[2] = 0.0625;
  return w;
}

DownsampleFilter fallback(FilterFitReport* report, const std::string& why) {
  if (report) {
    report->fitted = true;
    report->fallback = true;
    report->reason = why;
  }
  return DownsampleFilter::default_filter();
}

}  // namespace

std::string FilterFitReport::summary() const {
  if (!fitted) return "D: " + reason;
  std::ostringstream s;
  s << (fallback ? "D: default tent filter (fallback: " + reason + ")" : "D: least-squares optimal 11x11")
    << "; windows " << windows << ", equations " << equations << ", rank " << rank << "/" << kUnknowns
    << ", condition " << condition << "; sample rms optimal " << rms_optimal << ", default " << rms_default
    << ", impulse " << rms_impulse;
  return s.str();
}

std::vector<Rect> filter_fit_windows(GridSize level, const FilterFitOptions& options) {
  std::vector<Rect> out;
  const int64_t side = std::min({options.window, level.width, level.height});
  if (side < 3 * kMargin || options.max_windows <= 0) return out;
  int64_t nx = std::clamp<int64_t>(level.width / side, 1, 4),
          ny = std::clamp<int64_t>(level.height / side, 1, 4);
  while (nx * ny > options.max_windows) (nx >= ny ? nx : ny) -= 1;
  for (int64_t ty = 0; ty < ny; ++ty)
    for (int64_t tx = 0; tx < nx; ++tx) {
      const int64_t x = nx == 1 ? (level.width - side) / 2 : tx * (level.width - side) / (nx - 1);
      const int64_t y = ny == 1 ? (level.height - side) / 2 : ty * (level.height - side) / (ny - 1);
      out.push_back({x, y, side, side});
    }
  return out;
}

DownsampleFilter fit_optimal_filter(const std::vector<Rect>& windows,
                                    const std::vector<std::vector<int32_t>>& window_data,
                                    const FilterFitOptions& options, FilterFitReport* report) {
  if (report) *report = FilterFitReport{};
  if (windows.size() != window_data.size())
    throw std::invalid_argument("fit_optimal_filter: window count mismatch");
  const auto& orbits = symmetric_orbits();

  // Count the equations (the report's figure and the minimum for a fit).
  int64_t rows = 0;
  for (const Rect& r : windows)
    if (r.width > 2 * kMargin && r.height > 2 * kMargin)
      rows += (r.width - 2 * kMargin) * (r.height - 2 * kMargin);
  if (report) {
    report->fitted = true;
    report->windows = int(windows.size());
    report->equations = rows;
  }
  if (rows < 4 * kUnknowns) return fallback(report, "too few samples to fit (grid smaller than 24x24)");

  // The design matrix [A | y] (rows x 21, 32 MB for the default 16 windows) is never formed: each
  // window's rows are folded into R, the triangular factor of [A | y] = QR, by a QR of [R; rows]
  // (tall-skinny QR, as stable as one QR of the whole matrix). Everything below needs only R:
  // A = Q R_A with Q orthonormal, so column norms, A^T A and least-squares residuals are R's.
  // Forming A took a third of a 1201x1201 build, half of it page faults on the fresh matrices.
  constexpr int kCols = kUnknowns + 1;
  Eigen::MatrixXd R = Eigen::MatrixXd::Zero(kCols, kCols);
  Eigen::MatrixXd stacked;
  // Per equation the largest of |y| and |A row|: the activity test below needs only that and max |y|.
  std::vector<double> row_peak;
  row_peak.reserve(size_t(rows));
  double y_max = 0;
  std::vector<double> coarse;
  std::vector<std::vector<double>> predk(kOrbits);
  for (size_t wi = 0; wi < windows.size(); ++wi) {
    const Rect& r = windows[wi];
    if (r.width <= 2 * kMargin || r.height <= 2 * kMargin) continue;
    const GridSize fine{r.width, r.height};
    const GridSize cs{coarse_extent(r.width), coarse_extent(r.height)};
    if (int64_t(window_data[wi].size()) != r.width * r.height)
      throw std::invalid_argument("fit_optimal_filter: window data size mismatch");
    coarse.resize(size_t(cs.width * cs.height));
    for (int k = 0; k < kOrbits; ++k) {
      std::array<double, kOrbits> unit{};
      unit[size_t(k)] = 1.0;
      const DownsampleFilter basis =
          DownsampleFilter::from_orbit_weights(unit, DownsampleFilter::Kind::Custom);
      detail::downsample_real(basis, window_data[wi].data(), fine, coarse.data());
      predk[size_t(k)].resize(size_t(r.width * r.height));
      upsample_real(coarse.data(), fine, predk[size_t(k)].data());
    }
    const std::vector<double>& p0 = predk[0];
    const int64_t inner = (r.width - 2 * kMargin) * (r.height - 2 * kMargin);
    stacked.resize(kCols + inner, kCols);
    stacked.topRows(kCols) = R;
    int64_t rr = kCols;
    for (int64_t yy = kMargin; yy < r.height - kMargin; ++yy)
      for (int64_t xx = kMargin; xx < r.width - kMargin; ++xx, ++rr) {
        const size_t idx = size_t(yy * r.width + xx);
        const double yv = double(window_data[wi][idx]) - p0[idx];
        stacked(rr, kUnknowns) = yv;
        y_max = std::max(y_max, std::abs(yv));
        double peak = std::abs(yv);
        for (int k = 1; k < kOrbits; ++k) {
          const double v = predk[size_t(k)][idx] - orbits[size_t(k)].count * p0[idx];
          stacked(rr, k - 1) = v;
          peak = std::max(peak, std::abs(v));
        }
        row_peak.push_back(peak);
      }
    Eigen::HouseholderQR<Eigen::MatrixXd> fold(stacked);
    R = fold.matrixQR().topRows(kCols).triangularView<Eigen::Upper>();
  }
  const Eigen::MatrixXd RA = R.topLeftCorner(kUnknowns, kUnknowns);
  const Eigen::VectorXd z = R.col(kUnknowns).head(kUnknowns);             // Q^T y
  const double rho2 = R(kUnknowns, kUnknowns) * R(kUnknowns, kUnknowns);  // ||y - A a||^2 at the optimum

  // A lone feature (a spike, a single ridge) can make the matrix full rank with only a few hundred
  // informative equations: the fit would then chase that feature. Require enough of them.
  {
    const double tol = 1e-9 * std::max(1.0, y_max);
    int64_t active = 0;
    for (double peak : row_peak)
      if (peak > tol) ++active;
    if (report) report->active_equations = active;
    if (active < options.min_active_equations)
      return fallback(report,
                      "too few informative samples (" + std::to_string(active) + " non-flat equations)");
  }
  // Column scaling makes the rank/condition test about the shape of the data, not its amplitude.
  Eigen::VectorXd norms = RA.colwise().norm();
  const double max_norm = norms.maxCoeff();
  const double n = double(rows);
  auto rms_of = [&](const Eigen::VectorXd& a) { return std::sqrt(((z - RA * a).squaredNorm() + rho2) / n); };
  Eigen::VectorXd tent(kUnknowns);
  {
    auto w = default_orbit_weights();
    for (int k = 1; k < kOrbits; ++k) tent(k - 1) = w[size_t(k)];
  }
  if (report) {
    report->rms_impulse = std::sqrt((z.squaredNorm() + rho2) / n);
    report->rms_default = rms_of(tent);
  }
  if (!(max_norm > 0) || !std::isfinite(max_norm) || (report && report->active_equations == 0)) {
    if (report) report->condition = std::numeric_limits<double>::infinity();
    return fallback(report, "flat sample: every basis filter predicts the same surface");
  }
  Eigen::VectorXd scale(kUnknowns);
  for (int k = 0; k < kUnknowns; ++k) scale(k) = norms(k) > 1e-12 * max_norm ? 1.0 / norms(k) : 0.0;
  // A S = Q (R_A S): the pivoted QR of the small R_A S has the same R factor (rank) as that of A S,
  // and (R_A S)^T (R_A S) = (A S)^T (A S).
  const Eigen::MatrixXd As = RA * scale.asDiagonal();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(As);
  qr.setThreshold(1e-10);
  const int rank = int(qr.rank());
  Eigen::MatrixXd gram = As.transpose() * As;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(gram, Eigen::EigenvaluesOnly);
  const double lmin = eig.eigenvalues().minCoeff(), lmax = eig.eigenvalues().maxCoeff();
  const double cond = lmin > 0 ? std::sqrt(lmax / lmin) : std::numeric_limits<double>::infinity();
  if (report) {
    report->rank = rank;
    report->condition = cond;
  }
  if (rank < kUnknowns) return fallback(report, "rank-deficient sample (rank " + std::to_string(rank) + ")");
  if (!(cond <= options.max_condition)) return fallback(report, "ill-conditioned sample");

  Eigen::VectorXd a = scale.asDiagonal() * qr.solve(z);
  if (!a.allFinite()) return fallback(report, "non-finite solution");
  std::array<double, kOrbits> w{};
  double rest = 0;
  for (int k = 1; k < kOrbits; ++k) {
    w[size_t(k)] = a(k - 1);
    rest += orbits[size_t(k)].count * a(k - 1);
  }
  w[0] = 1.0 - rest;
  for (double v : w)
    if (!(std::abs(v) <= options.max_abs_tap)) return fallback(report, "filter coefficient out of bounds");
  const double rms_opt = rms_of(a);
  if (report) report->rms_optimal = rms_opt;
  const double rms_tent = rms_of(tent);
  if (!(rms_opt < rms_tent * (1.0 - 1e-9)))
    return fallback(report, "fit not better than the default filter on the sample");
  if (report) report->reason = "least squares fit";
  return DownsampleFilter::from_orbit_weights(w, DownsampleFilter::Kind::Optimal);
}

DownsampleFilter fit_optimal_filter(const int32_t* grid, GridSize level, const FilterFitOptions& options,
                                    FilterFitReport* report) {
  std::vector<Rect> windows = filter_fit_windows(level, options);
  std::vector<std::vector<int32_t>> data;
  for (const Rect& r : windows) {
    std::vector<int32_t> d(size_t(r.width * r.height));
    for (int64_t yy = 0; yy < r.height; ++yy)
      std::copy(grid + (r.y0 + yy) * level.width + r.x0, grid + (r.y0 + yy) * level.width + r.x0 + r.width,
                d.begin() + yy * r.width);
    data.push_back(std::move(d));
  }
  return fit_optimal_filter(windows, data, options, report);
}

}  // namespace terrain
