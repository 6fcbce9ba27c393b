#include "errsep/drivers/gpiod_io.hpp"

#include <gpiod.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace errsep::drivers {

struct GpiodIo::Impl {
  gpiod_chip* chip = nullptr;
  gpiod_line_bulk inputs = GPIOD_LINE_BULK_INITIALIZER;  // caller-owned bulk buffers: no
  gpiod_line_bulk events = GPIOD_LINE_BULK_INITIALIZER;  // allocation on the cyclic calls
  gpiod_line* output = nullptr;
  ~Impl() {
    if (chip) gpiod_chip_close(chip);  // releases every requested line
  }
};

GpiodIo::GpiodIo(io::GpioConfig cfg, std::string consumer)
    : cfg_(std::move(cfg)), consumer_(std::move(consumer)) {}

GpiodIo::~GpiodIo() = default;

void GpiodIo::configure() {
  auto impl = std::make_unique<Impl>();
  errno = 0;
  impl->chip = gpiod_chip_open_lookup(cfg_.chip.c_str());
  if (!impl->chip) {
    const int err = errno;
    throw std::runtime_error(
        "gpio: cannot open chip '" + cfg_.chip + "'" +
        (err ? std::string(": ") + std::strerror(err) : std::string()) +
        " (no such gpiochip on this machine? list them with `gpiodetect`; set [gpio] chip in the "
        "machine config, or remove [gpio] on a machine without digital I/O)");
  }
  const std::string chip_desc = "gpio chip '" + cfg_.chip + "' (" + gpiod_chip_name(impl->chip) +
                                ", " + std::to_string(gpiod_chip_num_lines(impl->chip)) + " lines)";
  auto get_line = [&](int offset, const char* role) {
    if (offset < 0 || static_cast<unsigned>(offset) >= gpiod_chip_num_lines(impl->chip))
      throw std::runtime_error(chip_desc + ": " + role + " = " + std::to_string(offset) +
                               ": no such line");
    gpiod_line* l = gpiod_chip_get_line(impl->chip, static_cast<unsigned>(offset));
    if (!l)
      throw std::runtime_error(chip_desc + ": " + role + " " + std::to_string(offset) + ": " +
                               std::strerror(errno));
    return l;
  };
  gpiod_line_bulk_init(&impl->inputs);
  if (cfg_.start_line >= 0)
    gpiod_line_bulk_add(&impl->inputs, get_line(cfg_.start_line, "start_line"));
  if (cfg_.trigger_line >= 0)
    gpiod_line_bulk_add(&impl->inputs, get_line(cfg_.trigger_line, "trigger_line"));
  if (gpiod_line_bulk_num_lines(&impl->inputs) > 0 &&
      gpiod_line_request_bulk_both_edges_events(&impl->inputs, consumer_.c_str()) != 0)
    throw std::runtime_error(chip_desc + ": cannot request input lines for edge events: " +
                             std::strerror(errno) + " (busy? see `gpioinfo`)");
  if (cfg_.output_line >= 0) {
    impl->output = get_line(cfg_.output_line, "output_line");
    if (gpiod_line_request_output(impl->output, consumer_.c_str(), 0) != 0)
      throw std::runtime_error(chip_desc + ": cannot request output_line " +
                               std::to_string(cfg_.output_line) + ": " + std::strerror(errno));
  }
  impl_ = std::move(impl);
}

std::size_t GpiodIo::input_count() const noexcept {
  return impl_ ? gpiod_line_bulk_num_lines(&impl_->inputs) : 0;
}

acq::IoStatus GpiodIo::wait_edge(acq::EdgeEvent& ev, std::chrono::milliseconds timeout) {
  if (!impl_ || gpiod_line_bulk_num_lines(&impl_->inputs) == 0)
    return acq::IoStatus::not_configured;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(timeout.count() / 1000);
  ts.tv_nsec = static_cast<long>((timeout.count() % 1000) * 1'000'000);
  gpiod_line_bulk_init(&impl_->events);
  const int r = gpiod_line_event_wait_bulk(&impl_->inputs, &ts, &impl_->events);
  if (r == 0) return acq::IoStatus::timeout;
  if (r < 0) return errno == EINTR ? acq::IoStatus::timeout : acq::IoStatus::fault;
  gpiod_line* line = gpiod_line_bulk_get_line(&impl_->events, 0);
  gpiod_line_event e{};
  if (!line || gpiod_line_event_read(line, &e) != 0) return acq::IoStatus::fault;
  ev.t_ns = static_cast<std::int64_t>(e.ts.tv_sec) * 1'000'000'000 + e.ts.tv_nsec;
  ev.line = gpiod_line_offset(line);
  ev.edge = e.event_type == GPIOD_LINE_EVENT_RISING_EDGE ? acq::Edge::rising : acq::Edge::falling;
  return acq::IoStatus::ok;
}

acq::IoStatus GpiodIo::set_output(unsigned line, bool value) {
  if (!impl_ || !impl_->output) return acq::IoStatus::not_configured;
  if (cfg_.output_line < 0 || line != static_cast<unsigned>(cfg_.output_line))
    return acq::IoStatus::out_of_range;
  return gpiod_line_set_value(impl_->output, value ? 1 : 0) == 0 ? acq::IoStatus::ok
                                                                 : acq::IoStatus::fault;
}

acq::IoStatus GpiodIo::read_inputs(int* values, std::size_t n) noexcept {
  if (!impl_ || gpiod_line_bulk_num_lines(&impl_->inputs) == 0)
    return acq::IoStatus::not_configured;
  if (n < gpiod_line_bulk_num_lines(&impl_->inputs)) return acq::IoStatus::out_of_range;
  return gpiod_line_get_value_bulk(&impl_->inputs, values) == 0 ? acq::IoStatus::ok
                                                                : acq::IoStatus::fault;
}

}  // namespace errsep::drivers
