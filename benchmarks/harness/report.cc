#include "benchmarks/harness/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "mgsr/core/subprocess.h"
#include "mgsr/io/file_util.h"

namespace mgsr::bench {
namespace {

namespace fs = std::filesystem;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

const nlohmann::json* Find(const nlohmann::json& j, std::initializer_list<const char*> path) {
  const nlohmann::json* node = &j;
  for (const char* key : path) {
    if (!node->is_object() || !node->contains(key)) return nullptr;
    node = &(*node)[key];
  }
  return node;
}

double Get(const nlohmann::json& j, std::initializer_list<const char*> path) {
  const nlohmann::json* node = Find(j, path);
  return node != nullptr && node->is_number() ? node->get<double>() : kNaN;
}

std::string Fixed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << v;
  return s.str();
}

// Enough digits that a report rebuilt from results.csv rounds exactly like the original.
std::string Precise(double v) {
  char buffer[40];
  std::snprintf(buffer, sizeof(buffer), "%.17g", v);
  return buffer;
}

std::string CsvEscape(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) out += c == '"' ? std::string("\"\"") : std::string(1, c);
  return out + "\"";
}

// One row of the per-scene tables.
std::string TableRow(const std::string& label, const RunRecord& r) {
  std::ostringstream s;
  s << "| " << label << " | " << Fixed(100 * r.nc, 2) << " | " << Fixed(1000 * r.cd, 2) << " | "
    << Fixed(r.psnr, 2) << " | " << Fixed(r.ssim, 4) << " | " << Fixed(r.psnr_aligned, 2) << " | "
    << Fixed(r.ssim_aligned, 4) << " | " << Fixed(r.offset_px, 2) << " | " << Fixed(r.fscore_1px, 3)
    << " | " << Fixed(100 * r.ceiling_nc, 2) << " | " << Fixed(1000 * r.ceiling_cd, 2) << " | "
    << Fixed(r.normal_deg, 1) << " | " << Fixed(r.t_warmup, 0) << " | " << Fixed(r.t_mutual, 0)
    << " | " << Fixed(r.t_mesh, 1) << " | " << Fixed(r.t_total, 0) << " | " << Fixed(r.peak_mb, 0)
    << " | " << Fixed(r.gaussians, 0) << " | " << Fixed(r.surfels, 0) << " | "
    << (r.ok ? "ok" : "**failed**: " + r.failure) << " |";
  return s.str();
}

const char* kTableHeader =
    "| method | NC x100 | CD x1000 | PSNR | SSIM | PSNR aligned | SSIM aligned | offset px | "
    "F 1px | ceiling NC | ceiling CD | normal deg | warm-up s | mutual s | mesh s | total s | "
    "peak MB | Gaussians | surfels | status |\n"
    "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | "
    "---: | ---: | ---: | ---: | ---: | ---: | --- |\n";

// Charts with gnuplot: one point per run, a colour per method, the Pareto front as a dashed step
// line (y higher is better, or lower with `lower_is_better`). Returns false when gnuplot is not
// installed.
bool WriteChart(const std::string& dir, const std::string& name, const std::string& title,
                const std::string& xlabel, const std::string& ylabel,
                const std::vector<std::string>& methods, const std::vector<RunRecord>& runs,
                double (*x_of)(const RunRecord&), double (*y_of)(const RunRecord&),
                bool lower_is_better = false) {
  const std::string gnuplot = FindProgram("gnuplot");
  if (gnuplot.empty()) return false;
  const std::string data = JoinPath(dir, name + ".dat");
  std::ofstream d(data);
  std::vector<double> xs, ys;
  std::vector<std::string> used;
  for (const std::string& m : methods) {
    bool any = false;
    for (const RunRecord& r : runs) {
      if (r.method != m || !r.measured) continue;
      const double x = x_of(r), y = y_of(r);
      if (!std::isfinite(x) || !std::isfinite(y)) continue;
      d << x << " " << y << "\n";
      xs.push_back(x);
      ys.push_back(y);
      any = true;
    }
    if (any) {
      used.push_back(m);
      d << "\n\n";
    }
  }
  std::vector<double> quality = ys;
  if (lower_is_better) {
    for (double& q : quality) q = -q;
  }
  const std::vector<int> front = ParetoFront(xs, quality);
  for (int i : front) d << xs[i] << " " << ys[i] << "\n";
  d.close();
  if (xs.empty()) return true;
  const std::string script = JoinPath(dir, name + ".gp");
  std::ofstream g(script);
  g << "set terminal pngcairo size 900,600 font 'sans,11'\n"
    << "set output '" << JoinPath(dir, name + ".png") << "'\n"
    << "set title '" << title << "'\nset xlabel '" << xlabel << "'\nset ylabel '" << ylabel
    << "'\nset key outside right\nset grid\n";
  g << "plot ";
  for (size_t i = 0; i < used.size(); ++i) {
    g << "'" << data << "' index " << i << " using 1:2 with points pt " << (5 + 2 * (i % 4))
      << " ps 1.6 title '" << used[i] << "', ";
  }
  g << "'" << data << "' index " << used.size()
    << " using 1:2 with steps dt 2 lw 2 lc rgb 'black' title 'Pareto front'\n";
  g.close();
  const ProgramResult r = RunProgram({gnuplot, script}, {}, JoinPath(dir, "gnuplot.log"));
  return r.exit_code == 0;
}

double TotalSeconds(const RunRecord& r) { return r.t_total; }
double NcX100(const RunRecord& r) { return 100 * r.nc; }
double AlignedPsnr(const RunRecord& r) { return r.psnr_aligned; }
double CdX1000(const RunRecord& r) { return 1000 * r.cd; }
double Primitives(const RunRecord& r) {
  return (std::isfinite(r.gaussians) ? r.gaussians : 0) +
         (std::isfinite(r.surfels) ? r.surfels : 0);
}

// Contact sheet of one scene: a row per method (label, then ground truth, composite, transmitted,
// reflected, depth, normal and signed depth error of the first test view; grey where a run has
// no such render).
bool WriteContactSheet(const std::string& path, const std::string& scene,
                       const std::vector<std::string>& methods,
                       const std::vector<RunRecord>& runs) {
  static const char* kColumns[] = {"gt",      "composite", "transmitted",  "reflected",
                                   "depth2d", "normal2d",  "depth2d_error"};
  std::vector<cv::Mat> rows;
  int tile = 0;
  std::string view;
  for (const RunRecord& r : runs) {
    if (r.scene != scene || !r.measured || !view.empty()) continue;
    std::vector<std::string> gts;
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(JoinPath(r.run_dir, "renders"), ec)) {
      const std::string f = e.path().filename().string();
      if (f.size() > 7 && f.compare(f.size() - 7, 7, "_gt.png") == 0)
        gts.push_back(f.substr(0, f.size() - 7));
    }
    std::sort(gts.begin(), gts.end());
    if (!gts.empty()) view = gts.front();
  }
  if (view.empty()) return false;
  for (const std::string& m : methods) {
    const RunRecord* run = nullptr;
    for (const RunRecord& r : runs) {
      if (r.scene == scene && r.method == m) run = &r;
    }
    if (run == nullptr) continue;
    std::vector<cv::Mat> tiles;
    for (const char* c : kColumns) {
      cv::Mat im;
      if (run->measured)
        im = cv::imread(JoinPath(run->run_dir, "renders/" + view + "_" + c + ".png"));
      if (im.empty()) {
        im = cv::Mat(std::max(tile, 64), std::max(tile, 64), CV_8UC3, cv::Scalar(90, 90, 90));
      }
      // Small renders are enlarged (nearest) so the column labels fit.
      if (tile == 0) tile = std::max(im.rows, 96);
      if (im.rows != tile) cv::resize(im, im, cv::Size(tile, tile), 0, 0, cv::INTER_NEAREST);
      tiles.push_back(im);
    }
    cv::Mat label(tile, 150, CV_8UC3, cv::Scalar(255, 255, 255));
    cv::putText(label, m, cv::Point(4, tile / 2), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    if (!run->ok) {
      cv::putText(label, "failed", cv::Point(4, tile / 2 + 18), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                  cv::Scalar(0, 0, 200), 1, cv::LINE_AA);
    }
    tiles.insert(tiles.begin(), label);
    cv::Mat row;
    cv::hconcat(tiles, row);
    rows.push_back(row);
  }
  if (rows.empty()) return false;
  cv::Mat header(22, rows[0].cols, CV_8UC3, cv::Scalar(255, 255, 255));
  for (int c = 0; c < static_cast<int>(std::size(kColumns)); ++c) {
    cv::putText(header, kColumns[c], cv::Point(150 + c * tile + 3, 16), cv::FONT_HERSHEY_SIMPLEX,
                0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  rows.insert(rows.begin(), header);
  cv::Mat sheet;
  cv::vconcat(rows, sheet);
  return cv::imwrite(path, sheet);
}

const RunRecord* FindRun(const std::vector<RunRecord>& runs, const std::string& scene,
                         const std::string& method) {
  for (const RunRecord& r : runs) {
    if (r.scene == scene && r.method == method && r.measured) return &r;
  }
  return nullptr;
}

std::string Signed(double v, int digits) {
  if (!std::isfinite(v)) return "-";
  return (v > 0 ? "+" : "") + Fixed(v, digits);
}

// The main case in one table: MGSR against the single-branch methods, the differences as
// "MGSR minus method" (NC and PSNR: positive is MGSR better; CD: negative is MGSR better).
void WriteMainCase(const ReportContext& c, const std::vector<RunRecord>& runs,
                   std::ostringstream& md) {
  const RunRecord* mgsr = FindRun(runs, c.main_scene, "mgsr");
  if (mgsr == nullptr) return;
  md << "\n## Main case (" << c.main_scene
     << "): MGSR against the single-branch methods\n\n"
        "Differences are MGSR minus the method: positive NC and PSNR, negative CD and time favour "
        "MGSR.\n\n"
        "| method | NC x100 | MGSR - it | CD x1000 | MGSR - it | PSNR | MGSR - it | PSNR aligned | "
        "MGSR - it | total s | MGSR - it | status |\n"
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n";
  for (const char* name : {"mgsr", "2dgs", "3dgs", "3dgs-ref"}) {
    const RunRecord* r = FindRun(runs, c.main_scene, name);
    if (r == nullptr) continue;
    md << "| " << name << " | " << Fixed(100 * r->nc, 2) << " | "
       << Signed(100 * (mgsr->nc - r->nc), 2) << " | " << Fixed(1000 * r->cd, 2) << " | "
       << Signed(1000 * (mgsr->cd - r->cd), 2) << " | " << Fixed(r->psnr, 2) << " | "
       << Signed(mgsr->psnr - r->psnr, 2) << " | " << Fixed(r->psnr_aligned, 2) << " | "
       << Signed(mgsr->psnr_aligned - r->psnr_aligned, 2) << " | " << Fixed(r->t_total, 0) << " | "
       << Signed(mgsr->t_total - r->t_total, 0) << " | "
       << (r->ok ? "ok" : "**failed**: " + r->failure) << " |\n";
  }
}

// Exposure compensation on the varying-light scenes: the default (affine) against --exposure off.
void WriteExposureComparison(const ReportContext& c, const std::vector<RunRecord>& runs,
                             std::ostringstream& md) {
  std::ostringstream rows;
  for (const SceneSpec& s : c.scenes) {
    const RunRecord* on = FindRun(runs, s.name, "mgsr");
    const RunRecord* off = FindRun(runs, s.name, "mgsr-no-exposure");
    if (on == nullptr || off == nullptr) continue;
    rows << "| " << s.name << " | " << Fixed(100 * off->nc, 2) << " | " << Fixed(100 * on->nc, 2)
         << " | " << Fixed(1000 * off->cd, 2) << " | " << Fixed(1000 * on->cd, 2) << " | "
         << Fixed(off->psnr, 2) << " | " << Fixed(on->psnr, 2) << " | "
         << Fixed(off->psnr_aligned, 2) << " | " << Fixed(on->psnr_aligned, 2) << " | "
         << Fixed(off->t_total, 0) << " | " << Fixed(on->t_total, 0) << " |\n";
  }
  if (rows.str().empty()) return;
  md << "\n## Exposure compensation on the varying-light scenes\n\n"
        "`mgsr` (per-view affine colour transform, the default) against `mgsr-no-exposure` "
        "(`--exposure off`), each pair on the same scene.\n\n"
        "| scene | NC off | NC on | CD off | CD on | PSNR off | PSNR on | aligned off | "
        "aligned on | s off | s on |\n"
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n"
     << rows.str();
}

// The quality-size study: per scene, the runs by model size, and the smallest budget that reaches
// the reference strategy's quality (NC and aligned PSNR each within 0.2 of it, or better).
void WriteBudgetStudy(const ReportContext& c, const std::vector<RunRecord>& runs,
                      std::ostringstream& md) {
  constexpr double kNcTolerance = 0.2, kPsnrTolerance = 0.2;  // NC x100 points, dB
  md << "\n## Quality against model size\n\n"
        "Each scene at every budget (a count per branch) with the MCMC strategy, and the "
        "reference strategy's run. \"Reaches the reference\" means NC x100 and aligned PSNR "
        "within "
     << Fixed(kNcTolerance, 1) << " points / " << Fixed(kPsnrTolerance, 1)
     << " dB of the reference run or better. ms/it is the training time (warm-up and mutual "
        "stage) per iteration.\n";
  for (const SceneSpec& s : c.scenes) {
    std::vector<const RunRecord*> rows;
    for (const RunRecord& r : runs) {
      if (r.scene == s.name && r.measured) rows.push_back(&r);
    }
    if (rows.empty()) continue;
    std::stable_sort(rows.begin(), rows.end(), [](const RunRecord* a, const RunRecord* b) {
      return Primitives(*a) < Primitives(*b);
    });
    const RunRecord* ref = FindRun(runs, s.name, "reference");
    const auto reaches_run = [&](const RunRecord& r, const RunRecord* target) {
      return target != nullptr && 100 * r.nc >= 100 * target->nc - kNcTolerance &&
             r.psnr_aligned >= target->psnr_aligned - kPsnrTolerance;
    };
    const auto reaches = [&](const RunRecord& r) { return reaches_run(r, ref); };
    // The first (smallest) budgeted run reaching `target`'s quality, other than `skip`.
    const auto smallest_reaching = [&](const RunRecord* target,
                                       const RunRecord* skip) -> const RunRecord* {
      for (const RunRecord* r : rows) {
        if (r != ref && r != skip && reaches_run(*r, target)) return r;
      }
      return nullptr;
    };
    md << "\n### " << s.name << "\n\n"
       << "| method | Gaussians | surfels | of the reference | NC x100 | CD x1000 | F 1px | "
          "offset px | PSNR aligned | ms/it | total s | reaches the reference |\n"
          "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |\n";
    for (const RunRecord* r : rows) {
      const std::string share = ref != nullptr && Primitives(*ref) > 0
                                    ? Fixed(100 * Primitives(*r) / Primitives(*ref), 0) + "%"
                                    : "-";
      md << "| " << r->method << " | " << Fixed(r->gaussians, 0) << " | " << Fixed(r->surfels, 0)
         << " | " << share << " | " << Fixed(100 * r->nc, 2) << " | " << Fixed(1000 * r->cd, 2)
         << " | " << Fixed(r->fscore_1px, 3) << " | " << Fixed(r->offset_px, 2) << " | "
         << Fixed(r->psnr_aligned, 2) << " | " << Fixed(MsPerIteration(*r), 1) << " | "
         << Fixed(r->t_total, 0) << " | "
         << (r == ref      ? "(the reference)"
             : reaches(*r) ? "yes"
                           : "no")
         << " |\n";
    }
    // --budget auto against the curve: the smallest given budget that reaches auto's quality.
    const RunRecord* automatic = FindRun(runs, s.name, "mcmc-auto");
    const RunRecord* smallest_at_auto = smallest_reaching(automatic, automatic);
    if (automatic != nullptr && smallest_at_auto != nullptr) {
      md << "\n`--budget auto` chose " << Fixed(Primitives(*automatic), 0)
         << " primitives; the smallest run reaching its quality is " << smallest_at_auto->method
         << " with " << Fixed(Primitives(*smallest_at_auto), 0) << " ("
         << Signed(100 * (Primitives(*automatic) / Primitives(*smallest_at_auto) - 1), 0)
         << "%: auto's count against it).\n";
    }
    const RunRecord* smallest = smallest_reaching(ref, nullptr);
    if (ref == nullptr) continue;
    md << "\n";
    if (smallest == nullptr) {
      md << "No budget reaches the reference's quality on " << s.name << ".\n";
    } else {
      md << "Smallest run that reaches the reference on " << s.name << ": **" << smallest->method
         << "**, " << Fixed(Primitives(*smallest), 0) << " primitives ("
         << Fixed(100 * Primitives(*smallest) / Primitives(*ref), 0) << "% of the reference's), "
         << Fixed(MsPerIteration(*smallest), 1) << " ms/it against "
         << Fixed(MsPerIteration(*ref), 1) << ".\n";
    }
  }
}

// Splits one CSV line (quoted fields with doubled quotes, as CsvEscape writes them).
std::vector<std::string> SplitCsvLine(const std::string& line) {
  std::vector<std::string> out(1);
  bool quoted = false;
  for (size_t i = 0; i < line.size(); ++i) {
    const char ch = line[i];
    if (quoted) {
      if (ch == '"' && i + 1 < line.size() && line[i + 1] == '"') {
        out.back() += '"';
        ++i;
      } else if (ch == '"') {
        quoted = false;
      } else {
        out.back() += ch;
      }
    } else if (ch == '"') {
      quoted = true;
    } else if (ch == ',') {
      out.emplace_back();
    } else {
      out.back() += ch;
    }
  }
  return out;
}

// The columns before `iterations` are the older reports' whole header; those still read back.
constexpr char kCsvHeaderV1[] =
    "scene,method,status,failure,nc,cd,psnr,ssim,psnr_aligned,ssim_aligned,warmup_s,mutual_s,"
    "mesh_s,total_s,wall_s,peak_mb,gaussians,surfels,offset_px,fscore_1px,ceiling_nc,ceiling_cd";
constexpr char kCsvHeaderV2[] =
    "scene,method,status,failure,nc,cd,psnr,ssim,psnr_aligned,ssim_aligned,warmup_s,mutual_s,"
    "mesh_s,total_s,wall_s,peak_mb,gaussians,surfels,offset_px,fscore_1px,ceiling_nc,ceiling_cd,"
    "iterations";
constexpr char kCsvHeader[] =
    "scene,method,status,failure,nc,cd,psnr,ssim,psnr_aligned,ssim_aligned,warmup_s,mutual_s,"
    "mesh_s,total_s,wall_s,peak_mb,gaussians,surfels,offset_px,fscore_1px,ceiling_nc,ceiling_cd,"
    "iterations,normal_deg";

}  // namespace

RunRecord::RunRecord()
    : nc(kNaN),
      cd(kNaN),
      psnr(kNaN),
      ssim(kNaN),
      psnr_aligned(kNaN),
      ssim_aligned(kNaN),
      offset_px(kNaN),
      fscore_1px(kNaN),
      ceiling_nc(kNaN),
      ceiling_cd(kNaN),
      normal_deg(kNaN),
      t_warmup(kNaN),
      t_mutual(kNaN),
      t_mesh(kNaN),
      t_total(kNaN),
      peak_mb(kNaN),
      gaussians(kNaN),
      surfels(kNaN),
      iterations(kNaN) {}

void ReadRunResult(int exit_code, int signal, bool timed_out, double timeout_seconds,
                   const std::string& log_tail, double nc_threshold, RunRecord* r) {
  r->ok = false;
  if (timed_out) {
    r->failure = "timeout after " + Fixed(timeout_seconds, 0) + " s";
    return;
  }
  if (signal != 0) {
    r->failure = "crash (signal " + std::to_string(signal) + ")";
    return;
  }
  if (exit_code != 0) {
    // mgsr_solve's one-line error, when it gave one.
    std::string line;
    const size_t at = log_tail.rfind("error: ");
    if (at != std::string::npos) line = log_tail.substr(at, log_tail.find('\n', at) - at);
    r->failure = exit_code == 1 && !line.empty()
                     ? line
                     : "crash (exit status " + std::to_string(exit_code) + ")";
    return;
  }
  std::string text;
  if (!ReadFileToString(JoinPath(r->run_dir, "metrics.json"), &text).ok()) {
    r->failure = "no metrics.json";
    return;
  }
  nlohmann::json m = nlohmann::json::parse(text, nullptr, false);
  if (m.is_discarded()) {
    r->failure = "metrics.json does not parse";
    return;
  }
  r->nc = Get(m, {"mesh", "nc"});
  r->cd = Get(m, {"mesh", "cd"});
  r->psnr = Get(m, {"test", "psnr"});
  r->ssim = Get(m, {"test", "ssim"});
  r->psnr_aligned = Get(m, {"test", "psnr_aligned"});
  r->ssim_aligned = Get(m, {"test", "ssim_aligned"});
  r->offset_px = Get(m, {"mesh", "signed_offset_median_px"});
  r->ceiling_nc = Get(m, {"mesh", "ceiling", "nc"});
  r->ceiling_cd = Get(m, {"mesh", "ceiling", "cd"});
  r->normal_deg = Get(m, {"depth", "end", "normal", "mean_deg"});
  if (const nlohmann::json* f = Find(m, {"mesh", "fscores"}); f != nullptr && f->is_array()) {
    for (const nlohmann::json& e : *f) {
      if (e.is_object() && e.value("footprints", 0.0) == 1.0)
        r->fscore_1px = e.value("fscore", kNaN);
    }
  }
  r->t_warmup = Get(m, {"seconds", "warmup"});
  r->t_mutual = Get(m, {"seconds", "mutual"});
  r->t_mesh = Get(m, {"seconds", "mesh"});
  r->t_total = Get(m, {"seconds", "total"});
  r->peak_mb = Get(m, {"peak_memory_mb"});
  r->gaussians = Get(m, {"counts", "gaussians"});
  r->surfels = Get(m, {"counts", "surfels"});
  const double warmup = std::max(Get(m, {"iterations", "warmup_2d"}),
                                 Get(m, {"iterations", "warmup_3d"})),
               mutual = Get(m, {"iterations", "mutual"});
  if (std::isfinite(warmup) || std::isfinite(mutual))
    r->iterations = (std::isfinite(warmup) ? warmup : 0) + (std::isfinite(mutual) ? mutual : 0);
  const double triangles = Get(m, {"mesh", "triangles"});
  r->measured = true;
  // NaN is written as null by the JSON writer: a missing test score means a NaN somewhere.
  if (!std::isfinite(r->psnr) || !std::isfinite(r->ssim)) {
    r->failure = "NaN in the test scores";
  } else if (!(triangles > 0)) {
    r->failure = "empty mesh";
  } else if (std::isfinite(r->nc) && r->nc < nc_threshold) {
    r->failure = "NC " + Fixed(r->nc, 3) + " below " + Fixed(nc_threshold, 2);
  } else {
    r->ok = true;
  }
}

Status ReadResultsCsv(const std::string& path, const std::string& work,
                      std::vector<RunRecord>* runs) {
  std::string text;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &text));
  std::istringstream in(text);
  std::string line;
  if (!std::getline(in, line) ||
      (line != kCsvHeader && line != kCsvHeaderV2 && line != kCsvHeaderV1))
    return Status::Error(path + ": not a results.csv of this harness (header differs)");
  const size_t columns = line == kCsvHeader ? 24 : line == kCsvHeaderV2 ? 23 : 22;
  runs->clear();
  int line_number = 1;
  while (std::getline(in, line)) {
    ++line_number;
    if (line.empty()) continue;
    const std::vector<std::string> f = SplitCsvLine(line);
    if (f.size() != columns)
      return Status::Error(path + ": line " + std::to_string(line_number) + " has " +
                           std::to_string(f.size()) + " fields, expected " +
                           std::to_string(columns));
    RunRecord r;
    r.scene = f[0];
    r.method = f[1];
    r.ok = f[2] == "ok";
    r.failure = f[3];
    r.run_dir = JoinPath(work, "runs/" + r.scene + "/" + r.method);
    double* fields[] = {&r.nc,           &r.cd,           &r.psnr,         &r.ssim,
                        &r.psnr_aligned, &r.ssim_aligned, &r.t_warmup,     &r.t_mutual,
                        &r.t_mesh,       &r.t_total,      &r.wall_seconds, &r.peak_mb,
                        &r.gaussians,    &r.surfels,      &r.offset_px,    &r.fscore_1px,
                        &r.ceiling_nc,   &r.ceiling_cd,   &r.iterations,   &r.normal_deg};
    for (size_t k = 0; k + 4 < columns; ++k) {
      const std::string& v = f[4 + k];
      if (v.empty()) continue;
      char* end = nullptr;
      *fields[k] = std::strtod(v.c_str(), &end);
      if (end == v.c_str() || *end != '\0')
        return Status::Error(path + ": line " + std::to_string(line_number) + ": '" + v +
                             "' is not a number");
      if (k != 10) r.measured = true;  // wall time is known for every run
    }
    runs->push_back(std::move(r));
  }
  return Status::Ok();
}

Status ReadReportContext(const std::string& path, ReportContext* c) {
  std::string text;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &text));
  const nlohmann::json j = nlohmann::json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return Status::Error(path + ": not a JSON object");
  try {
    c->title = j.at("title").get<std::string>();
    c->command = j.at("command").get<std::string>();
    c->commit = j.at("commit").get<std::string>();
    c->date = j.at("date").get<std::string>();
    c->machine = j.at("machine").get<std::string>();
    c->threads = j.at("threads").get<int>();
    c->nc_threshold = j.at("nc_threshold").get<double>();
    c->main_scene = j.at("main_scene").get<std::string>();
    c->budget_study = j.value("budget_study", false);
  } catch (const nlohmann::json::exception& e) {
    return Status::Error(path + ": " + e.what());
  }
  return Status::Ok();
}

double MsPerIteration(const RunRecord& r) {
  if (!(r.iterations > 0)) return kNaN;
  return 1000 * (r.t_warmup + r.t_mutual) / r.iterations;
}

std::vector<int> ParetoFront(const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<int> order(x.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  // By cost, then by quality (best first); keep a point when it beats every cheaper one.
  std::sort(order.begin(), order.end(),
            [&](int a, int b) { return x[a] != x[b] ? x[a] < x[b] : y[a] > y[b]; });
  std::vector<int> front;
  double best = -std::numeric_limits<double>::infinity();
  for (int i : order) {
    if (y[i] > best) {
      front.push_back(i);
      best = y[i];
    }
  }
  return front;
}

Status WriteReport(const std::string& dir, const ReportContext& c,
                   const std::vector<RunRecord>& runs) {
  MGSR_RETURN_IF_ERROR(MakeDirectories(JoinPath(dir, "charts")));
  MGSR_RETURN_IF_ERROR(MakeDirectories(JoinPath(dir, "contact")));

  // results.csv
  std::ostringstream csv;
  csv << kCsvHeader << "\n";
  for (const RunRecord& r : runs) {
    csv << r.scene << "," << r.method << "," << (r.ok ? "ok" : "failed") << ","
        << CsvEscape(r.failure);
    for (double v : {r.nc,           r.cd,         r.psnr,       r.ssim,       r.psnr_aligned,
                     r.ssim_aligned, r.t_warmup,   r.t_mutual,   r.t_mesh,     r.t_total,
                     r.wall_seconds, r.peak_mb,    r.gaussians,  r.surfels,    r.offset_px,
                     r.fscore_1px,   r.ceiling_nc, r.ceiling_cd, r.iterations, r.normal_deg}) {
      csv << "," << (std::isfinite(v) ? Precise(v) : "");
    }
    csv << "\n";
  }
  MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(JoinPath(dir, "results.csv"), csv.str()));
  const nlohmann::json context = {{"title", c.title},
                                  {"command", c.command},
                                  {"commit", c.commit},
                                  {"date", c.date},
                                  {"machine", c.machine},
                                  {"threads", c.threads},
                                  {"nc_threshold", c.nc_threshold},
                                  {"main_scene", c.main_scene},
                                  {"budget_study", c.budget_study}};
  MGSR_RETURN_IF_ERROR(
      WriteStringToFileAtomic(JoinPath(dir, "context.json"), context.dump(2) + "\n"));

  std::vector<std::string> method_names;
  for (const MethodSpec& m : c.methods) method_names.push_back(m.name);

  // Charts.
  const std::string charts = JoinPath(dir, "charts");
  bool have_gnuplot =
      WriteChart(charts, "time_vs_nc", "Time against mesh quality (one point per method and scene)",
                 "total time (s)", "NC x100", method_names, runs, TotalSeconds, NcX100);
  have_gnuplot = WriteChart(charts, "time_vs_psnr", "Time against test PSNR (exposure-aligned)",
                            "total time (s)", "PSNR aligned (dB)", method_names, runs, TotalSeconds,
                            AlignedPsnr) &&
                 have_gnuplot;
  have_gnuplot = WriteChart(charts, "count_vs_psnr", "Model size against test PSNR (aligned)",
                            "primitives (Gaussians + surfels)", "PSNR aligned (dB)", method_names,
                            runs, Primitives, AlignedPsnr) &&
                 have_gnuplot;
  have_gnuplot = WriteChart(charts, "count_vs_nc", "Model size against mesh normal consistency",
                            "primitives (Gaussians + surfels)", "NC x100", method_names, runs,
                            Primitives, NcX100) &&
                 have_gnuplot;
  have_gnuplot = WriteChart(charts, "count_vs_cd", "Model size against Chamfer distance (exact)",
                            "primitives (Gaussians + surfels)", "CD x1000 (lower is better)",
                            method_names, runs, Primitives, CdX1000, true) &&
                 have_gnuplot;

  // README.md
  std::ostringstream md;
  md << "# " << c.title << "\n\n"
     << "Made by `" << c.command << "` on " << c.date << ", commit `" << c.commit << "`.\n"
     << "Machine: " << c.machine << "; " << c.threads << " threads. Every number here comes from "
     << "this run (each run's `metrics.json` under `runs/` of the work folder); nothing is reused "
     << "from earlier runs.\n\n";
  if (!c.rebuilt.empty())
    md << "The tables and charts were rebuilt from this run's results.csv on " << c.rebuilt
       << " (`mgsr_bench --report_only`); no run was repeated.\n\n";
  md << "NC and CD compare the TSDF mesh with the scene's exact mesh (NC x100, CD x1000, as in "
     << "the paper); PSNR/SSIM are on held-out views, raw and exposure-aligned (an affine colour "
     << "fit per test image on the mask, since test views are lit differently). Times are "
     << "wall-clock seconds of the solver's stages; peak MB is the process's peak resident "
     << "memory. A run fails on a crash, an error exit, a timeout, NaN, an empty mesh, or NC below "
     << Fixed(c.nc_threshold, 2) << ".\n\n";
  md << "## Scenes\n\n| scene | stresses |\n| --- | --- |\n";
  for (const SceneSpec& s : c.scenes) md << "| " << s.name << " | " << s.stresses << " |\n";
  md << "\n## Methods\n\n| method | what |\n| --- | --- |\n";
  for (const MethodSpec& m : c.methods) md << "| " << m.name << " | " << m.description << " |\n";

  md << "\n## Results per scene\n";
  for (const SceneSpec& s : c.scenes) {
    md << "\n### " << s.name << ": " << s.stresses << "\n\n" << kTableHeader;
    for (const MethodSpec& m : c.methods) {
      for (const RunRecord& r : runs) {
        if (r.scene == s.name && r.method == m.name) md << TableRow(m.name, r) << "\n";
      }
    }
  }

  // Averages of each method over the scenes where every main method succeeded.
  md << "\n## Averages\n\nMean over the scenes on which the method ran and was measured "
        "(the number of scenes in brackets; the status counts the failed ones).\n\n"
     << kTableHeader;
  for (const MethodSpec& m : c.methods) {
    RunRecord mean;
    int n = 0;
    double* fields[] = {&mean.nc,           &mean.cd,           &mean.psnr,     &mean.ssim,
                        &mean.psnr_aligned, &mean.ssim_aligned, &mean.t_warmup, &mean.t_mutual,
                        &mean.t_mesh,       &mean.t_total,      &mean.peak_mb,  &mean.gaussians,
                        &mean.surfels};
    for (double* f : fields) *f = 0;
    int failed = 0;
    for (const RunRecord& r : runs) {
      if (r.method != m.name) continue;
      failed += !r.ok;
      if (!r.measured) continue;
      const double values[] = {r.nc,           r.cd,        r.psnr,     r.ssim,   r.psnr_aligned,
                               r.ssim_aligned, r.t_warmup,  r.t_mutual, r.t_mesh, r.t_total,
                               r.peak_mb,      r.gaussians, r.surfels};
      for (int k = 0; k < 13; ++k) *fields[k] += values[k];
      ++n;
    }
    if (n == 0) continue;
    for (double* f : fields) *f /= n;
    mean.ok = failed == 0;
    mean.failure = std::to_string(failed) + " failed";
    md << TableRow(m.name + " (" + std::to_string(n) + ")", mean) << "\n";
  }

  WriteMainCase(c, runs, md);
  WriteExposureComparison(c, runs, md);
  if (c.budget_study) WriteBudgetStudy(c, runs, md);

  md << "\n## Stability matrix\n\n| method |";
  for (const SceneSpec& s : c.scenes) md << " " << s.name << " |";
  md << "\n| --- |";
  for (size_t i = 0; i < c.scenes.size(); ++i) md << " --- |";
  md << "\n";
  for (const MethodSpec& m : c.methods) {
    md << "| " << m.name << " |";
    for (const SceneSpec& s : c.scenes) {
      std::string cell = " ";
      for (const RunRecord& r : runs) {
        if (r.scene == s.name && r.method == m.name)
          cell = r.ok ? "ok" : "**failed**: " + r.failure;
      }
      md << " " << cell << " |";
    }
    md << "\n";
  }

  md << "\n## Charts\n\n";
  if (have_gnuplot) {
    md << "One point per run that was measured (runs failed on the NC threshold included). "
          "Dashed: the Pareto front (no other run is both faster, or smaller, and better).\n\n"
       << "![time vs NC](charts/time_vs_nc.png)\n\n![time vs PSNR](charts/time_vs_psnr.png)\n\n"
       << "![primitives vs PSNR](charts/count_vs_psnr.png)\n\n"
       << "![primitives vs NC](charts/count_vs_nc.png)\n\n"
       << "![primitives vs CD](charts/count_vs_cd.png)\n";
  } else {
    md << "gnuplot is not installed, so no charts were drawn (the data is in results.csv).\n";
  }

  md << "\n## Contact sheets\n\nFirst test view of each scene; rows are methods; columns: ground "
        "truth, composite, transmitted, reflected, depth, normal (2DGS; 3DGS-only methods show "
        "their own expected depth and the normals of that depth).\n\n";
  for (const SceneSpec& s : c.scenes) {
    const std::string rel = "contact/" + s.name + ".png";
    if (WriteContactSheet(JoinPath(dir, rel), s.name, method_names, runs))
      md << "### " << s.name << "\n\n![" << s.name << "](" << rel << ")\n\n";
  }
  return WriteStringToFileAtomic(JoinPath(dir, "README.md"), md.str());
}

}  // namespace mgsr::bench
