#include "mgsr/sfm/colmap_pipeline.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "mgsr/core/progress.h"
#include "mgsr/core/subprocess.h"
#include "mgsr/core/timer.h"
#include "mgsr/io/colmap_model.h"
#include "mgsr/io/file_util.h"
#include "mgsr/io/image_io.h"

namespace mgsr {
namespace {

namespace fs = std::filesystem;

bool HasImageExtension(const std::string& name) {
  std::string ext = fs::path(name).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".jpg" || ext == ".jpeg" || ext == ".png" || ext == ".bmp" || ext == ".tif" ||
         ext == ".tiff";
}

std::string Join(const std::vector<std::string>& names, size_t max_names) {
  std::string out;
  for (size_t i = 0; i < names.size() && i < max_names; ++i) out += (i ? ", " : "") + names[i];
  if (names.size() > max_names) out += ", ... (" + std::to_string(names.size()) + " in all)";
  return out;
}

// "[a/b" at `pos` (after the prefix): a and b, or false.
bool ParseFraction(const std::string& text, size_t pos, long* a, long* b) {
  char* end = nullptr;
  const char* p = text.c_str() + pos;
  *a = std::strtol(p, &end, 10);
  if (end == p || *end != '/') return false;
  p = end + 1;
  *b = std::strtol(p, &end, 10);
  return end != p && *a >= 0 && *b > 0;
}

// Runs one colmap command as a named, timed step.
class StepRunner {
 public:
  StepRunner(std::string colmap, const ColmapPipelineOptions& options,
             ColmapPipelineSummary* summary, int num_images)
      : colmap_(std::move(colmap)), options_(options), summary_(summary), num_images_(num_images) {}

  Status Run(const std::string& step, std::vector<std::string> args) {
    if (options_.log) options_.log(step + " ...");
    {
      std::ofstream log(summary_->log_path, std::ios::app);
      log << "\n==== " << step << ": colmap";
      for (const std::string& a : args) log << ' ' << a;
      log << "\n";
    }
    args.insert(args.begin(), colmap_);
    Timer timer;
    // While it runs: a progress line every 5 s from what colmap has written to the log. Each poll
    // reads only what was appended since the last one (the mapper writes megabytes on large
    // captures); a line not yet finished waits for the next poll. The latest count is kept across
    // polls: the meter may show it on a later one.
    std::error_code ec;
    uint64_t read_to = fs::file_size(summary_->log_path, ec);
    std::string unfinished_line, unit;
    double done = 0, total = 0;
    ProgressMeter meter(step, "", 5.0, options_.log);
    // A step whose log says nothing countable for a while (exhaustive matching of a few photos is
    // one block) still gets a line at least every quiet_seconds, so a run never looks hung.
    double last_line_at = 0;
    const auto show_progress = [&] {
      std::ifstream in(summary_->log_path, std::ios::binary);
      if (in && !ec) {
        in.seekg(static_cast<std::streamoff>(read_to));
        std::string text = unfinished_line + std::string((std::istreambuf_iterator<char>(in)),
                                                         std::istreambuf_iterator<char>());
        read_to += text.size() - unfinished_line.size();
        const size_t last_newline = text.rfind('\n');
        unfinished_line = last_newline == std::string::npos ? text : text.substr(last_newline + 1);
        text.resize(last_newline == std::string::npos ? 0 : last_newline + 1);
        if (LatestColmapProgress(text, num_images_, &done, &total, &unit)) meter.set_unit(unit);
        if (total > 0 && meter.UpdateAt(done, total, timer.ElapsedSeconds()))
          last_line_at = timer.ElapsedSeconds();
      }
      const double now = timer.ElapsedSeconds();
      if (now - last_line_at >= options_.quiet_seconds) {
        char line[160];
        std::snprintf(line, sizeof(line), "%s: running, %.0f s", step.c_str(), now);
        std::string text = line;
        if (total > 0)
          text += " (" + std::to_string(static_cast<long>(done)) + "/" +
                  std::to_string(static_cast<long>(total)) + " " + unit + " so far)";
        options_.log(text);
        last_line_at = now;
      }
    };
    // Headless: colmap links Qt, which needs a display unless told otherwise.
    const ProgramResult r =
        RunProgram(args, {"QT_QPA_PLATFORM=offscreen"}, summary_->log_path, 0,
                   options_.log ? std::function<void()>(show_progress) : std::function<void()>());
    summary_->steps.push_back({step, timer.ElapsedSeconds()});
    if (!r.started) return Status::Error(colmap_ + ": could not be executed (" + step + ")");
    if (r.exit_code != 0) {
      return Status::Error("colmap " + args[1] + " failed with exit status " +
                           std::to_string(r.exit_code) + " during " + step + "; see " +
                           summary_->log_path);
    }
    if (options_.log) {
      char line[128];
      std::snprintf(line, sizeof(line), "%s done in %.1f s", step.c_str(),
                    summary_->steps.back().seconds);
      options_.log(line);
    }
    return Status::Ok();
  }

 private:
  std::string colmap_;
  const ColmapPipelineOptions& options_;
  ColmapPipelineSummary* summary_;
  int num_images_;
};

std::string Threads(const ColmapPipelineOptions& o) { return std::to_string(o.num_threads); }

// The mapper's models under sparse/ (0, 1, ...); the one with the most registered images wins.
Status PickLargestModel(const std::string& sparse, std::string* best_dir, ColmapModel* best,
                        int* num_models) {
  *num_models = 0;
  size_t best_count = 0;
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(sparse, ec)) {
    if (!entry.is_directory()) continue;
    ColmapModel model;
    if (!ReadColmapModel(entry.path().string(), &model).ok()) continue;
    ++*num_models;
    if (model.images.size() > best_count) {
      best_count = model.images.size();
      *best = std::move(model);
      *best_dir = entry.path().string();
    }
  }
  return Status::Ok();
}

// Masks named exactly as the photos (what image_undistorter looks up), as links to whichever
// naming the user chose.
Status LinkMasksUnderImageNames(const std::string& masks, const std::vector<std::string>& names,
                                const std::string& link_dir) {
  MGSR_RETURN_IF_ERROR(MakeDirectories(link_dir));
  for (const std::string& name : names) {
    const std::string stem = FileStem(name);
    std::string found;
    for (const std::string& c : {name, stem + ".png", stem + ".jpg", name + ".png"}) {
      if (FileExists(JoinPath(masks, c))) {
        found = JoinPath(masks, c);
        break;
      }
    }
    if (found.empty())
      return Status::Error(masks + ": no mask for photo " + name + " (expected " + stem + ".png)");
    std::error_code ec;
    fs::create_symlink(fs::absolute(found), JoinPath(link_dir, name), ec);
    if (ec) return Status::Error(link_dir + ": cannot create a link: " + ec.message());
  }
  return Status::Ok();
}

// "Mean reprojection error: 0.35px" and "Points: 1003" from model_analyzer's output.
void ParseModelAnalyzer(const std::string& text, ColmapPipelineSummary* summary) {
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const size_t colon = line.rfind(": ");
    if (colon == std::string::npos) continue;
    const std::string value = line.substr(colon + 2);
    if (line.find("Mean reprojection error") != std::string::npos) {
      summary->mean_reprojection_error = std::atof(value.c_str());
    } else if (line.find("] Points") != std::string::npos || line.rfind("Points", 0) == 0) {
      summary->points = std::atol(value.c_str());
    }
  }
}

}  // namespace

Status ColmapPipelineOptions::Validate() const {
  if (images.empty()) return Status::Error("--images: a folder of photos is required");
  if (workspace.empty()) return Status::Error("--workspace: an output folder is required");
  if (exhaustive_max_images < 2)
    return Status::Error("--exhaustive_max_images: must be at least 2");
  if (max_image_size < 100) return Status::Error("--max_image_size: must be at least 100");
  static const std::set<std::string> kModels = {"SIMPLE_PINHOLE", "PINHOLE", "SIMPLE_RADIAL",
                                                "RADIAL",         "OPENCV",  "FULL_OPENCV"};
  if (!kModels.count(camera_model)) {
    return Status::Error("--camera_model: '" + camera_model +
                         "' is not one of SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, "
                         "FULL_OPENCV");
  }
  return Status::Ok();
}

bool LatestColmapProgress(const std::string& log_text, int num_images, double* done, double* total,
                          std::string* unit) {
  // From the last line back: the first line that reports progress is the latest.
  size_t end = log_text.size();
  while (end > 0) {
    const size_t begin = log_text.rfind('\n', end - 1);
    const size_t from = begin == std::string::npos ? 0 : begin + 1;
    const std::string line = log_text.substr(from, end - from);
    end = begin == std::string::npos ? 0 : begin;
    long a = 0, b = 0, c = 0, d = 0;
    size_t at;
    for (const char* prefix : {"Processed file [", "Matching image [", "Undistorting image ["}) {
      if ((at = line.find(prefix)) != std::string::npos &&
          ParseFraction(line, at + std::strlen(prefix), &a, &b)) {
        *done = static_cast<double>(a);
        *total = static_cast<double>(b);
        *unit = "images";
        return true;
      }
    }
    const char* block = "Matching block [";
    if ((at = line.find(block)) != std::string::npos &&
        ParseFraction(line, at + std::strlen(block), &a, &b)) {
      const size_t second = line.find(", ", at);
      if (second != std::string::npos && ParseFraction(line, second + 2, &c, &d)) {
        *done = static_cast<double>((a - 1) * d + c);
        *total = static_cast<double>(b * d);
        *unit = "blocks";
        return true;
      }
    }
    const char* registering = "Registering image #";
    if ((at = line.find(registering)) != std::string::npos && num_images > 0) {
      const size_t open = line.find('(', at);
      char* stop = nullptr;
      const long k =
          open == std::string::npos ? -1 : std::strtol(line.c_str() + open + 1, &stop, 10);
      if (k >= 0 && stop != nullptr && *stop == ')') {
        *done = static_cast<double>(k);
        *total = static_cast<double>(num_images);
        *unit = "images placed";
        return true;
      }
    }
  }
  return false;
}

Status ListImageFiles(const std::string& dir, std::vector<std::string>* names) {
  names->clear();
  if (!DirectoryExists(dir)) return Status::Error(dir + ": folder of photos does not exist");
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(dir, ec)) {
    if (entry.is_regular_file() && HasImageExtension(entry.path().filename().string()))
      names->push_back(entry.path().filename().string());
  }
  if (ec) return Status::Error(dir + ": cannot list the folder: " + ec.message());
  std::sort(names->begin(), names->end());
  return Status::Ok();
}

Status RunColmapPipeline(const ColmapPipelineOptions& options, ColmapPipelineSummary* summary) {
  *summary = ColmapPipelineSummary();
  MGSR_RETURN_IF_ERROR(options.Validate());
  const std::string colmap = FindProgram(options.colmap);
  if (colmap.empty()) {
    return Status::Error(options.colmap +
                         ": program not found (install it with `sudo apt-get install colmap`, or "
                         "pass its path with --colmap)");
  }
  std::vector<std::string> names;
  MGSR_RETURN_IF_ERROR(ListImageFiles(options.images, &names));
  if (names.empty()) {
    return Status::Error(options.images +
                         ": no photos in the folder (.jpg, .jpeg, .png, .bmp, .tif, .tiff)");
  }
  if (names.size() < 3) {
    return Status::Error(options.images + ": " + std::to_string(names.size()) +
                         " photo(s); at least 3 are needed");
  }
  summary->images_given = static_cast<int>(names.size());

  // A previous run's outputs are replaced, never mixed with this run's.
  const std::string& ws = options.workspace;
  MGSR_RETURN_IF_ERROR(MakeDirectories(ws));
  const std::string database = JoinPath(ws, "database.db");
  const std::string sparse = JoinPath(ws, "sparse");
  const std::string dense = JoinPath(ws, "dense");
  const std::string dense_tmp = JoinPath(ws, "dense.partial");
  std::error_code ec;
  for (const std::string& p :
       {database, database + "-shm", database + "-wal", sparse, dense, dense_tmp}) {
    fs::remove_all(p, ec);
  }
  MGSR_RETURN_IF_ERROR(MakeDirectories(sparse));
  summary->log_path = JoinPath(ws, "colmap.log");
  fs::remove(summary->log_path, ec);

  // colmap reads the stored pixels and ignores EXIF orientation: photos a camera stored turned
  // (portrait phone shots) are handed to it upright, the others linked as they are.
  std::string photos = options.images;
  {
    std::vector<int> orientations;
    size_t turned = 0;
    for (const std::string& n : names) {
      orientations.push_back(ExifOrientation(JoinPath(options.images, n)));
      turned += orientations.back() != 1;
    }
    if (turned > 0) {
      photos = JoinPath(ws, "photos_upright");
      fs::remove_all(photos, ec);
      MGSR_RETURN_IF_ERROR(MakeDirectories(photos));
      for (size_t i = 0; i < names.size(); ++i) {
        const std::string from = JoinPath(options.images, names[i]);
        const std::string to = JoinPath(photos, names[i]);
        const int orientation = orientations[i];
        if (orientation == 1) {
          fs::create_symlink(fs::absolute(from), to, ec);
          if (ec) return Status::Error(to + ": cannot link the photo: " + ec.message());
          continue;
        }
        Image image;
        MGSR_RETURN_IF_ERROR(ReadImage(from, &image));
        MGSR_RETURN_IF_ERROR(WriteImage(to, ApplyExifOrientation(image, orientation)));
      }
      if (options.log)
        options.log("photos: " + std::to_string(turned) + " of " + std::to_string(names.size()) +
                    " turned upright as their EXIF orientation says (colmap reads the stored "
                    "pixels), in " +
                    photos);
    }
  }
  // Only the photos: colmap would otherwise try every file in the folder (a K.txt, notes) and
  // count them in its progress.
  const std::string image_list = JoinPath(ws, "image_list.txt");
  {
    std::string list;
    for (const std::string& n : names) list += n + "\n";
    MGSR_RETURN_IF_ERROR(WriteStringToFileAtomic(image_list, list));
  }
  StepRunner run(colmap, options, summary, static_cast<int>(names.size()));
  MGSR_RETURN_IF_ERROR(run.Run(
      "feature extraction",
      {"feature_extractor", "--database_path", database, "--image_path", photos,
       "--image_list_path", image_list, "--ImageReader.single_camera",
       options.single_camera ? "1" : "0", "--ImageReader.camera_model", options.camera_model,
       "--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", Threads(options),
       "--SiftExtraction.max_image_size", std::to_string(options.max_image_size)}));

  const bool exhaustive = static_cast<int>(names.size()) <= options.exhaustive_max_images;
  if (exhaustive) {
    MGSR_RETURN_IF_ERROR(
        run.Run("exhaustive matching",
                {"exhaustive_matcher", "--database_path", database, "--SiftMatching.use_gpu", "0",
                 "--SiftMatching.num_threads", Threads(options)}));
  } else {
    // Photos taken in order (a walk around the object); no vocabulary tree needed.
    MGSR_RETURN_IF_ERROR(
        run.Run("sequential matching",
                {"sequential_matcher", "--database_path", database, "--SiftMatching.use_gpu", "0",
                 "--SiftMatching.num_threads", Threads(options), "--SequentialMatching.overlap",
                 "20", "--SequentialMatching.quadratic_overlap", "1",
                 "--SequentialMatching.loop_detection", "0"}));
  }

  const Status mapped =
      run.Run("mapping", {"mapper", "--database_path", database, "--image_path", photos,
                          "--output_path", sparse, "--Mapper.num_threads", Threads(options),
                          // colmap drops models under 10 images by default; a small photo set
                          // should still reconstruct (3 is what the solver needs).
                          "--Mapper.min_model_size", "3"});
  std::string model_dir;
  ColmapModel model;
  MGSR_RETURN_IF_ERROR(PickLargestModel(sparse, &model_dir, &model, &summary->num_models));
  if (summary->num_models == 0) {
    return Status::Error("colmap mapper reconstructed no model from the " +
                         std::to_string(names.size()) + " photos in " + options.images +
                         " (too little texture or overlap?); see " + summary->log_path);
  }
  if (!mapped.ok()) return mapped;

  std::set<std::string> registered;
  for (const ColmapImage& im : model.images) registered.insert(im.name);
  for (const std::string& n : names) {
    if (!registered.count(n)) summary->unregistered.push_back(n);
  }
  summary->images_registered = static_cast<int>(registered.size());
  if (summary->images_registered < 3) {
    return Status::Error("only " + std::to_string(summary->images_registered) + " of " +
                         std::to_string(names.size()) + " photos registered (not registered: " +
                         Join(summary->unregistered, 10) + "); see " + summary->log_path);
  }

  // Undistorted into a temporary folder, renamed when complete: a failed run never leaves a
  // dense/ that looks usable.
  MGSR_RETURN_IF_ERROR(
      run.Run("undistortion", {"image_undistorter", "--image_path", photos, "--input_path",
                               model_dir, "--output_path", dense_tmp, "--output_type", "COLMAP"}));
  if (!options.masks.empty()) {
    if (!DirectoryExists(options.masks))
      return Status::Error(options.masks + ": folder of masks does not exist");
    const std::string links = JoinPath(ws, "masks.links");
    const std::string masks_tmp = JoinPath(ws, "masks.partial");
    fs::remove_all(links, ec);
    fs::remove_all(masks_tmp, ec);
    std::vector<std::string> registered_names(registered.begin(), registered.end());
    MGSR_RETURN_IF_ERROR(LinkMasksUnderImageNames(options.masks, registered_names, links));
    // The same undistortion maps the masks pixel for pixel onto the undistorted photos.
    MGSR_RETURN_IF_ERROR(run.Run(
        "mask undistortion", {"image_undistorter", "--image_path", links, "--input_path", model_dir,
                              "--output_path", masks_tmp, "--output_type", "COLMAP"}));
    fs::rename(JoinPath(masks_tmp, "images"), JoinPath(dense_tmp, "masks"), ec);
    if (ec)
      return Status::Error(masks_tmp + ": cannot move the undistorted masks: " + ec.message());
    fs::remove_all(links, ec);
    fs::remove_all(masks_tmp, ec);
  }
  fs::rename(dense_tmp, dense, ec);
  if (ec) return Status::Error(dense + ": cannot create: " + ec.message());
  summary->scene_dir = dense;

  // Statistics of the model the solver will read.
  const std::string analysis = JoinPath(ws, "model_analyzer.txt");
  fs::remove(analysis, ec);
  const ProgramResult r =
      RunProgram({colmap, "model_analyzer", "--path", JoinPath(dense, "sparse")},
                 {"QT_QPA_PLATFORM=offscreen"}, analysis);
  std::string text;
  if (r.exit_code == 0 && ReadFileToString(analysis, &text).ok()) {
    ParseModelAnalyzer(text, summary);
  } else {
    summary->points = static_cast<long>(model.points.size());
  }
  return Status::Ok();
}

}  // namespace mgsr
