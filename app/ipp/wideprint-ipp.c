//
// wideprint-ipp: the IPP Everywhere Printer Application of a wideprint print server
// (docs/ipp.md).  Built on PAPPL (https://www.msweet.org/pappl); C because PAPPL is C.
//
// One PAPPL system, one IPP printer per printer of the wideprint server.  The program does
// not talk to the server itself: `wideprint serve --ipp` (app/ipp/bridge.py) starts it with
// a configuration file (the printers, from their printer profiles) and speaks a line
// protocol with it on stdin/stdout (docs/ipp.md, "The bridge protocol"):
//
//   this program -> bridge   submit / cancel / forget lines: a spooled document to queue
//   bridge -> this program   printer / job lines: the server's printer and job states
//
// so the HTTP API, its token and the settings schema stay in one place (the bridge is an
// ordinary client of the API).  Documents go to the wideprint queue as they came (the RIP
// reads JPEG, PNG, TIFF, PDF and PostScript itself); only PWG/Apple raster, which PAPPL
// streams line by line, is written to a TIFF per page first.
//
// Usage: wideprint-ipp CONFIG   (CONFIG: docs/ipp.md, "The configuration file")
//

#include <pappl/pappl.h>
#include <tiffio.h>
#include <errno.h>
#include <fcntl.h>
#include <limits.h>
#include <pthread.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>


#define WP_MAX_PRINTERS	32
#define WP_MAX_DPI	8
#define WP_MAX_PAGES	1000		// PWG raster pages per job
#define WP_LINE		8192		// longest protocol line


// -- configuration and state ----------------------------------------------------------------

#define WP_MAX_TYPES 16			// media-type values offered (PAPPL keeps 32)

typedef struct wp_printer_s		// One printer of the wideprint server
{
  char		name[64];		// its name on the server (the IPP printer's name too)
  char		make_model[128];	// printer-make-and-model
  int		roll_mm,		// the paper width: measured by the printer, else the profile's
		roll_len_mm,		// the roll's remaining length as the server tracks it (0: unknown)
		print_mm,		// the widest printable span ([printer] print_width_mm)
		margin_hmm,		// side margins, hundredths of mm
		max_length_mm,		// the longest print (the RIP's limit)
		num_dpi,		// dpi modes ([encoder] dpi_modes)
		dpi[WP_MAX_DPI],
		default_dpi;
  char		media_names[2][16][64];	// storage for the driver's media names: two banks,
  int		bank, num_media;	// the one in use and the one rewritten on a change
  // media-type: "stationery" and the server's media library (docs/media.md), the loaded
  // roll's media (docs/ipp.md "The paper"); names kept in two banks like the sizes
  char		type_names[2][WP_MAX_TYPES][64],
		roll_type[64];		// the loaded roll's media ("": none named)
  int		num_types;
  char		types[WP_MAX_TYPES][64];	// from the bridge's media line
  pappl_printer_t *printer;		// the PAPPL printer
  // state from the server (bridge "printer" lines)
  char		state[32];		// idle, printing, offline, fault
  int		paused;
  char		reasons[128];		// IPP printer-state-reasons keywords, comma separated
  char		message[512];		// the fault or pause reason in plain words
} wp_printer_t;

typedef struct wp_track_s		// One submission waiting for its wideprint job
{
  int		tag;			// our number for it (the protocol's TAG)
  int		wpid;			// the wideprint job id (0: not queued yet)
  char		state[32];		// "" (no answer yet), queued, held, printing, done, failed, cancelled, error
  int		copies_done, copies, strokes_done, strokes_total;
  char		message[1024];
  int		seq;			// bumped on every update
  struct wp_track_s *next;
} wp_track_t;

typedef struct wp_pages_s		// PWG raster job: the pages written so far
{
  TIFF		*tif;			// the page being written
  int		num_pages;
  char		*pages[WP_MAX_PAGES];	// TIFF files, one per page
  unsigned	width, height, bpl;	// the page being written
} wp_pages_t;

static struct
{
  char		listen[256],		// "localhost" or an address ("*": every address)
		hostname[256],		// host name in the printer URIs
		spool[1024],		// PAPPL's spool directory
		log[1024],		// log file ("-": stderr)
		auth[16],		// "token" or "none"
		token[256],		// the API token (the password of Basic authentication)
		name[128],		// the system's name
		version[64],		// wideprint's version (printer-firmware-string-version)
		web_url[512];		// the shop's web page (printer-more-info leads there)
  int		port;
  pappl_loglevel_t loglevel;
  int		num_printers;
  wp_printer_t	printers[WP_MAX_PRINTERS];
} wp;

static pthread_mutex_t	io_lock = PTHREAD_MUTEX_INITIALIZER;	// stdout and the tracks
static pthread_cond_t	io_cond = PTHREAD_COND_INITIALIZER;
static wp_track_t	*tracks = NULL;
static int		next_tag = 1;
static pappl_system_t	*wp_system = NULL;


// -- helpers ---------------------------------------------------------------------------------

static void
send_line(const char *fmt, ...)		// one protocol line to the bridge (stdout)
{
  va_list ap;

  pthread_mutex_lock(&io_lock);
  va_start(ap, fmt);
  vfprintf(stdout, fmt, ap);
  va_end(ap);
  fputc('\n', stdout);
  fflush(stdout);
  pthread_mutex_unlock(&io_lock);
}


static void
clean_field(char *dst, const char *src, size_t size)	// no tabs or line ends in a field
{
  size_t i;

  for (i = 0; src && src[i] && i + 1 < size; i ++)
    dst[i] = (src[i] == '\t' || src[i] == '\n' || src[i] == '\r') ? ' ' : src[i];
  dst[i] = '\0';
}


static int
split_tabs(char *line, char **fields, int max)		// split a line at tabs, in place
{
  int n = 0;

  fields[n ++] = line;
  while (n < max && (line = strchr(line, '\t')) != NULL)
  {
    *line++ = '\0';
    fields[n ++] = line;
  }
  return (n);
}


static wp_printer_t *
find_printer(const char *name)
{
  int i;

  for (i = 0; i < wp.num_printers; i ++)
    if (!strcmp(wp.printers[i].name, name))
      return (wp.printers + i);
  return (NULL);
}


// -- configuration file ----------------------------------------------------------------------

static bool
load_config(const char *path)
{
  FILE		*fp;
  char		line[1024], *key, *value, *end;
  wp_printer_t	*p = NULL;
  int		linenum = 0;

  if ((fp = fopen(path, "r")) == NULL)
  {
    fprintf(stderr, "wideprint-ipp: %s: %s\n", path, strerror(errno));
    return (false);
  }

  memset(&wp, 0, sizeof(wp));
  strcpy(wp.listen, "localhost");
  strcpy(wp.auth, "token");
  strcpy(wp.name, "wideprint");
  strcpy(wp.log, "-");
  wp.port = 8632;
  wp.loglevel = PAPPL_LOGLEVEL_INFO;

  while (fgets(line, sizeof(line), fp))
  {
    linenum ++;
    if ((end = strchr(line, '\n')) != NULL)
      *end = '\0';
    for (key = line; *key == ' '; key ++);
    if (!*key || *key == '#')
      continue;
    if ((value = strchr(key, ' ')) != NULL)
      *value++ = '\0';
    else
      value = key + strlen(key);

    if (!strcmp(key, "printer"))
    {
      if (wp.num_printers >= WP_MAX_PRINTERS)
        break;
      p = wp.printers + wp.num_printers ++;
      papplCopyString(p->name, value, sizeof(p->name));
      strcpy(p->state, "idle");
      p->roll_mm = p->print_mm = 1000;
      p->max_length_mm = 50000;
    }
    else if (!strcmp(key, "listen"))
      papplCopyString(wp.listen, value, sizeof(wp.listen));
    else if (!strcmp(key, "hostname"))
      papplCopyString(wp.hostname, value, sizeof(wp.hostname));
    else if (!strcmp(key, "port"))
      wp.port = atoi(value);
    else if (!strcmp(key, "spool"))
      papplCopyString(wp.spool, value, sizeof(wp.spool));
    else if (!strcmp(key, "log"))
      papplCopyString(wp.log, value, sizeof(wp.log));
    else if (!strcmp(key, "loglevel"))
      wp.loglevel = !strcmp(value, "debug") ? PAPPL_LOGLEVEL_DEBUG : !strcmp(value, "warn") ? PAPPL_LOGLEVEL_WARN : PAPPL_LOGLEVEL_INFO;
    else if (!strcmp(key, "auth"))
      papplCopyString(wp.auth, value, sizeof(wp.auth));
    else if (!strcmp(key, "token"))
      papplCopyString(wp.token, value, sizeof(wp.token));
    else if (!strcmp(key, "name"))
      papplCopyString(wp.name, value, sizeof(wp.name));
    else if (!strcmp(key, "version"))
      papplCopyString(wp.version, value, sizeof(wp.version));
    else if (!strcmp(key, "web-url"))
      papplCopyString(wp.web_url, value, sizeof(wp.web_url));
    else if (p && !strcmp(key, "make-and-model"))
      papplCopyString(p->make_model, value, sizeof(p->make_model));
    else if (p && !strcmp(key, "roll-width-mm"))
      p->roll_mm = atoi(value);
    else if (p && !strcmp(key, "print-width-mm"))
      p->print_mm = atoi(value);
    else if (p && !strcmp(key, "margin-mm"))
      p->margin_hmm = (int)(strtod(value, NULL) * 100.0 + 0.5);
    else if (p && !strcmp(key, "max-length-mm"))
      p->max_length_mm = atoi(value);
    else if (p && !strcmp(key, "default-dpi"))
      p->default_dpi = atoi(value);
    else if (p && !strcmp(key, "dpi"))
    {
      char *s = value;
      while (*s && p->num_dpi < WP_MAX_DPI)
      {
        long d = strtol(s, &end, 10);
        if (end == s)
          break;
        p->dpi[p->num_dpi ++] = (int)d;
        s = end;
      }
    }
    else
    {
      fprintf(stderr, "wideprint-ipp: %s:%d: unknown key '%s'\n", path, linenum, key);
      fclose(fp);
      return (false);
    }
  }
  fclose(fp);

  if (wp.num_printers == 0 || !wp.spool[0])
  {
    fprintf(stderr, "wideprint-ipp: %s: needs a spool directory and at least one printer\n", path);
    return (false);
  }
  if (!strcmp(wp.auth, "token") && !wp.token[0])
  {
    fprintf(stderr, "wideprint-ipp: %s: auth token without a token\n", path);
    return (false);
  }
  for (int i = 0; i < wp.num_printers; i ++)
  {
    p = wp.printers + i;
    if (p->num_dpi == 0 || p->roll_mm <= 0 || p->print_mm < p->roll_mm)
    {
      fprintf(stderr, "wideprint-ipp: %s: printer %s: needs dpi modes and a roll no wider than the print width\n", path, p->name);
      return (false);
    }
    if (!p->default_dpi)
      p->default_dpi = p->dpi[0];
    if (!p->make_model[0])
      snprintf(p->make_model, sizeof(p->make_model), "wideprint %s", p->name);
  }
  return (true);
}


// -- the bridge: submissions and their states -------------------------------------------------

static wp_track_t *
track_new(void)
{
  wp_track_t *t = calloc(1, sizeof(wp_track_t));

  pthread_mutex_lock(&io_lock);
  t->tag  = next_tag ++;
  t->next = tracks;
  tracks  = t;
  pthread_mutex_unlock(&io_lock);
  return (t);
}


static void
track_free(wp_track_t *t)
{
  wp_track_t **pp;

  pthread_mutex_lock(&io_lock);
  for (pp = &tracks; *pp; pp = &(*pp)->next)
  {
    if (*pp == t)
    {
      *pp = t->next;
      break;
    }
  }
  pthread_mutex_unlock(&io_lock);
  send_line("forget\t%d", t->tag);
  free(t);
}


static bool
final_state(const char *state)
{
  return (!strcmp(state, "done") || !strcmp(state, "failed") || !strcmp(state, "cancelled") || !strcmp(state, "error"));
}


//
// 'submit_and_wait()' - Queue one file on the wideprint server and follow its job to its end.
//
// The IPP job stays "processing" while its wideprint job waits, prints or is held; the
// job-state-message says where it is (docs/ipp.md, "Job state").  A Cancel-Job cancels
// the wideprint job; a job cancelled or failed on the server ends the IPP job the same way.
//

static bool
submit_and_wait(pappl_job_t *job, wp_printer_t *p, const char *path, const char *format,
                pappl_pr_options_t *options, int copies)
{
  wp_track_t		*t = track_new();
  ipp_attribute_t	*attr;
  int			xdpi = 0, seen = 0, copies_seen = 0;
  bool			cancel_sent = false, ok;
  char			jobname[256], user[256], media_type[64];
  const char		*quality, *intent;

  // printer-resolution only when the client asked for one: otherwise the preset decides
  if ((attr = papplJobGetAttribute(job, "printer-resolution")) != NULL)
  {
    int yres;
    ipp_res_t units;
    xdpi = ippGetResolution(attr, 0, &yres, &units);
    if (units == IPP_RES_PER_CM)
      xdpi = (int)(xdpi * 2.54 + 0.5);
  }
  switch (options->print_quality)
  {
    case IPP_QUALITY_DRAFT : quality = "draft"; break;
    case IPP_QUALITY_HIGH :  quality = "high"; break;
    default :                quality = "normal"; break;
  }
  if ((intent = cupsGetOption("print-rendering-intent", options->num_vendor, options->vendor)) == NULL)
    intent = "auto";
  clean_field(jobname, papplJobGetName(job), sizeof(jobname));
  clean_field(user, papplJobGetUsername(job), sizeof(user));

  papplJobSetImpressions(job, copies);
  papplJobSetMessage(job, "Sending the document to the wideprint queue.");
  clean_field(media_type, options->media.type, sizeof(media_type));
  send_line("submit\t%d\t%s\t%s\t%s\t%d\t%s\t%d\t%d\t%s\t%s\t%s\t%s", t->tag, p->name, format, path,
            copies, quality, xdpi, (int)options->orientation_requested, intent, user, jobname,
            media_type);

  pthread_mutex_lock(&io_lock);
  for (;;)
  {
    struct timespec	deadline;

    while (t->seq == seen && !(papplJobIsCanceled(job) && !cancel_sent))
    {
      clock_gettime(CLOCK_REALTIME, &deadline);
      deadline.tv_nsec += 250000000;
      if (deadline.tv_nsec >= 1000000000)
      {
        deadline.tv_sec ++;
        deadline.tv_nsec -= 1000000000;
      }
      pthread_cond_timedwait(&io_cond, &io_lock, &deadline);
      if (papplSystemIsShutdown(wp_system))
        break;
    }
    if (papplSystemIsShutdown(wp_system))
    {
      pthread_mutex_unlock(&io_lock);
      papplJobSetMessage(job, "The Printer Application stopped.");
      track_free(t);
      return (false);
    }
    if (papplJobIsCanceled(job) && !cancel_sent)
    {
      cancel_sent = true;
      pthread_mutex_unlock(&io_lock);
      send_line("cancel\t%d", t->tag);
      pthread_mutex_lock(&io_lock);
      continue;
    }
    seen = t->seq;

    // the wideprint job's state, in the IPP job's words
    if (t->copies_done > copies_seen)
    {
      papplJobSetImpressionsCompleted(job, t->copies_done - copies_seen);
      copies_seen = t->copies_done;
    }
    if (!strcmp(t->state, "queued"))
      papplJobSetMessage(job, "Job %d in the wideprint queue%s%s.", t->wpid, t->message[0] ? ": " : "", t->message);
    else if (!strcmp(t->state, "held"))
      papplJobSetMessage(job, "Job %d held in the wideprint queue%s%s.", t->wpid, t->message[0] ? ": " : "", t->message);
    else if (!strcmp(t->state, "printing"))
      papplJobSetMessage(job, "Job %d printing: copy %d of %d, stroke %d of %d.", t->wpid,
                         t->copies_done + 1 > t->copies ? t->copies : t->copies_done + 1, t->copies,
                         t->strokes_done, t->strokes_total);
    else if (final_state(t->state))
      break;
  }
  pthread_mutex_unlock(&io_lock);

  if (!strcmp(t->state, "done"))
  {
    papplJobSetMessage(job, "Job %d printed.", t->wpid);
    ok = true;
  }
  else if (!strcmp(t->state, "cancelled"))
  {
    papplJobSetMessage(job, "Job %d cancelled%s%s.", t->wpid, t->message[0] ? ": " : "", t->message);
    if (!papplJobIsCanceled(job))
      papplJobCancel(job);		// cancelled on the server: the IPP job is cancelled too
    ok = true;
  }
  else
  {
    if (t->wpid)
      papplJobSetMessage(job, "Job %d failed: %s", t->wpid, t->message);
    else
      papplJobSetMessage(job, "Not queued: %s", t->message);
    papplJobSetReasons(job, PAPPL_JREASON_DOCUMENT_UNPRINTABLE_ERROR, PAPPL_JREASON_NONE);
    ok = false;
  }
  papplLogJob(job, ok ? PAPPL_LOGLEVEL_INFO : PAPPL_LOGLEVEL_ERROR, "wideprint job %d: %s %s", t->wpid, t->state, t->message);
  track_free(t);
  return (ok);
}


static bool
copies_ok(pappl_job_t *job, int copies)
{
  if (copies <= 100)
    return (true);
  papplJobSetMessage(job, "At most 100 copies per job (asked for %d).", copies);
  papplJobSetReasons(job, PAPPL_JREASON_JOB_DATA_INSUFFICIENT, PAPPL_JREASON_NONE);
  return (false);
}


//
// 'print_original()' - The MIME filter and raw-print callback: the spooled document goes to
//                      the wideprint queue as it came.
//

static bool
print_original(pappl_job_t *job, pappl_device_t *device, void *data)
{
  wp_printer_t		*p = find_printer(papplPrinterGetName(papplJobGetPrinter(job)));
  pappl_pr_options_t	*options;
  bool			ok;

  (void)device;
  (void)data;

  if (!p)
    return (false);
  options = papplJobCreatePrintOptions(job, 0, true);
  ok = copies_ok(job, options->copies) &&
       submit_and_wait(job, p, papplJobGetFilename(job), papplJobGetFormat(job), options, options->copies);
  papplJobDeletePrintOptions(options);
  return (ok);
}


static bool
print_file_cb(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device)
{
  (void)options;
  return (print_original(job, device, NULL));
}


// -- PWG and Apple raster: one TIFF per page ----------------------------------------------------

static bool
raster_start_job(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device)
{
  (void)options;
  (void)device;
  papplJobSetData(job, calloc(1, sizeof(wp_pages_t)));
  return (papplJobGetData(job) != NULL);
}


static bool
raster_start_page(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device, unsigned page)
{
  wp_pages_t		*pages = (wp_pages_t *)papplJobGetData(job);
  cups_page_header2_t	*h = &options->header;
  char			path[1024];
  int			fd, samples, photometric;

  (void)device;

  if (pages->num_pages >= WP_MAX_PAGES)
    return (false);
  if (h->cupsBitsPerColor != 8)
  {
    papplLogJob(job, PAPPL_LOGLEVEL_ERROR, "Page %u: %u bits per colour; this printer takes 8-bit raster.", page, h->cupsBitsPerColor);
    papplJobSetReasons(job, PAPPL_JREASON_DOCUMENT_FORMAT_ERROR, PAPPL_JREASON_NONE);
    return (false);
  }
  switch (h->cupsColorSpace)
  {
    case CUPS_CSPACE_SRGB :
    case CUPS_CSPACE_RGB :
    case CUPS_CSPACE_ADOBERGB :
        samples = 3, photometric = PHOTOMETRIC_RGB;
        break;
    case CUPS_CSPACE_SW :
    case CUPS_CSPACE_W :
        samples = 1, photometric = PHOTOMETRIC_MINISBLACK;
        break;
    case CUPS_CSPACE_K :
        samples = 1, photometric = PHOTOMETRIC_MINISWHITE;
        break;
    case CUPS_CSPACE_CMYK :
        samples = 4, photometric = PHOTOMETRIC_SEPARATED;
        break;
    default :
        papplLogJob(job, PAPPL_LOGLEVEL_ERROR, "Page %u: colour space %u is not printed.", page, h->cupsColorSpace);
        papplJobSetReasons(job, PAPPL_JREASON_DOCUMENT_FORMAT_ERROR, PAPPL_JREASON_NONE);
        return (false);
  }
  if (h->cupsBitsPerPixel != 8U * (unsigned)samples || h->cupsBytesPerLine != h->cupsWidth * (unsigned)samples)
  {
    papplLogJob(job, PAPPL_LOGLEVEL_ERROR, "Page %u: unexpected raster layout.", page);
    return (false);
  }

  // the page's TIFF, in PAPPL's spool directory, private to this job
  if ((fd = papplJobOpenFile(job, path, sizeof(path), wp.spool, "tif", "w")) < 0)
    return (false);
  close(fd);
  {
    char name[64];
    snprintf(name, sizeof(name), "-p%u.tif", page);
    size_t n = strlen(path);
    if (n > 4 && !strcmp(path + n - 4, ".tif"))
    {
      unlink(path);
      path[n - 4] = '\0';
      strncat(path, name, sizeof(path) - strlen(path) - 1);
    }
  }
  if ((pages->tif = TIFFOpen(path, "w")) == NULL)
    return (false);
  pages->pages[pages->num_pages ++] = strdup(path);
  pages->width  = h->cupsWidth;
  pages->height = h->cupsHeight;
  pages->bpl    = h->cupsBytesPerLine;

  TIFFSetField(pages->tif, TIFFTAG_IMAGEWIDTH, h->cupsWidth);
  TIFFSetField(pages->tif, TIFFTAG_IMAGELENGTH, h->cupsHeight);
  TIFFSetField(pages->tif, TIFFTAG_BITSPERSAMPLE, 8);
  TIFFSetField(pages->tif, TIFFTAG_SAMPLESPERPIXEL, samples);
  TIFFSetField(pages->tif, TIFFTAG_PHOTOMETRIC, photometric);
  if (photometric == PHOTOMETRIC_SEPARATED)
    TIFFSetField(pages->tif, TIFFTAG_INKSET, INKSET_CMYK);
  TIFFSetField(pages->tif, TIFFTAG_PLANARCONFIG, PLANARCONFIG_CONTIG);
  TIFFSetField(pages->tif, TIFFTAG_COMPRESSION, COMPRESSION_LZW);
  TIFFSetField(pages->tif, TIFFTAG_ROWSPERSTRIP, 16);
  TIFFSetField(pages->tif, TIFFTAG_RESOLUTIONUNIT, RESUNIT_INCH);
  TIFFSetField(pages->tif, TIFFTAG_XRESOLUTION, (float)h->HWResolution[0]);
  TIFFSetField(pages->tif, TIFFTAG_YRESOLUTION, (float)h->HWResolution[1]);
  papplLogJob(job, PAPPL_LOGLEVEL_INFO, "Page %u: %ux%u pixels at %ux%u dpi to %s.", page, h->cupsWidth, h->cupsHeight, h->HWResolution[0], h->HWResolution[1], path);
  return (true);
}


static bool
raster_write_line(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device, unsigned y, const unsigned char *line)
{
  wp_pages_t *pages = (wp_pages_t *)papplJobGetData(job);

  (void)options;
  (void)device;
  if (!pages->tif || y >= pages->height)
    return (false);
  return (TIFFWriteScanline(pages->tif, (void *)line, y, 0) == 1);
}


static bool
raster_end_page(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device, unsigned page)
{
  wp_pages_t *pages = (wp_pages_t *)papplJobGetData(job);

  (void)options;
  (void)device;
  (void)page;
  if (pages->tif)
  {
    TIFFClose(pages->tif);
    pages->tif = NULL;
  }
  return (true);
}


static bool
raster_end_job(pappl_job_t *job, pappl_pr_options_t *options, pappl_device_t *device)
{
  wp_pages_t	*pages = (wp_pages_t *)papplJobGetData(job);
  wp_printer_t	*p = find_printer(papplPrinterGetName(papplJobGetPrinter(job)));
  bool		ok = p != NULL;
  int		i;

  (void)device;
  if (pages->tif)
  {
    TIFFClose(pages->tif);
    pages->tif = NULL;
  }
  // each page is one wideprint job (the queue's unit), one after another
  for (i = 0; ok && i < pages->num_pages && !papplJobIsCanceled(job); i ++)
    ok = submit_and_wait(job, p, pages->pages[i], "image/tiff", options, 1);
  for (i = 0; i < pages->num_pages; i ++)
  {
    unlink(pages->pages[i]);
    free(pages->pages[i]);
  }
  free(pages);
  papplJobSetData(job, NULL);
  return (ok);
}


static void
identify_cb(pappl_printer_t *printer, pappl_identify_actions_t actions, const char *message)
{
  char text[512];

  (void)actions;
  clean_field(text, message ? message : "", sizeof(text));
  send_line("identify\t%s\t%s", papplPrinterGetName(printer), text);
}


// -- the device: nothing is written to it (the wideprint server owns the printer) ---------------

static bool
dev_open(pappl_device_t *device, const char *device_uri, const char *name)
{
  (void)device;
  (void)device_uri;
  (void)name;
  return (true);
}


static void
dev_close(pappl_device_t *device)
{
  (void)device;
}


static ssize_t
dev_read(pappl_device_t *device, void *buffer, size_t bytes)
{
  (void)device;
  (void)buffer;
  (void)bytes;
  return (0);
}


static ssize_t
dev_write(pappl_device_t *device, const void *buffer, size_t bytes)
{
  (void)device;
  (void)buffer;
  return ((ssize_t)bytes);
}


static pappl_preason_t
dev_status(pappl_device_t *device)
{
  (void)device;
  return (PAPPL_PREASON_NONE);
}


// -- printer state from the server ------------------------------------------------------------

static pappl_preason_t
reason_bits(const char *reasons)
{
  pappl_preason_t bits = PAPPL_PREASON_NONE;

  if (strstr(reasons, "media-empty"))
    bits |= PAPPL_PREASON_MEDIA_EMPTY;
  if (strstr(reasons, "media-needed"))
    bits |= PAPPL_PREASON_MEDIA_NEEDED;
  if (strstr(reasons, "media-jam"))
    bits |= PAPPL_PREASON_MEDIA_JAM;
  if (strstr(reasons, "offline"))
    bits |= PAPPL_PREASON_OFFLINE;
  if (strstr(reasons, "media-low"))	// the roll running low: a warning (docs/ipp.md)
    bits |= PAPPL_PREASON_MEDIA_LOW;
  if (strstr(reasons, "other"))
    bits |= PAPPL_PREASON_OTHER;
  return (bits);
}

#define WP_REASONS (PAPPL_PREASON_MEDIA_EMPTY | PAPPL_PREASON_MEDIA_LOW | PAPPL_PREASON_MEDIA_NEEDED | PAPPL_PREASON_MEDIA_JAM | PAPPL_PREASON_OFFLINE | PAPPL_PREASON_OTHER)


static ipp_t *
extra_attrs(wp_printer_t *p)		// what PAPPL 1.3 does not make from the driver data
{
  ipp_t *attrs = ippNew();
  static const char * const intents[] = { "auto", "absolute", "perceptual", "relative", "saturation" };

  if (p && p->roll_len_mm <= 0)
  {
    // the loaded roll whose length nobody measured (docs/ipp.md "The paper"): PAPPL can only
    // say a ready medium by a PWG name, which states a length; so media-col-ready is ours -
    // the measured width, any length from 25 mm up to the longest print (a range, as for a
    // custom size), "length unknown" in words - and there is no media-ready keyword
    ipp_t *col = ippNew(), *size = ippNew();
    char info[128];

    ippAddInteger(size, IPP_TAG_ZERO, IPP_TAG_INTEGER, "x-dimension", p->roll_mm * 100);
    ippAddRange(size, IPP_TAG_ZERO, "y-dimension", 2500, p->max_length_mm * 100);
    ippAddInteger(col, IPP_TAG_ZERO, IPP_TAG_INTEGER, "media-bottom-margin", 0);
    snprintf(info, sizeof(info), "roll %d mm wide, length unknown", p->roll_mm);
    ippAddString(col, IPP_TAG_ZERO, IPP_TAG_TEXT, "media-info", NULL, info);
    ippAddInteger(col, IPP_TAG_ZERO, IPP_TAG_INTEGER, "media-left-margin", p->margin_hmm);
    ippAddInteger(col, IPP_TAG_ZERO, IPP_TAG_INTEGER, "media-right-margin", p->margin_hmm);
    ippAddCollection(col, IPP_TAG_ZERO, "media-size", size);
    ippAddString(col, IPP_TAG_ZERO, IPP_CONST_TAG(IPP_TAG_KEYWORD), "media-source", NULL, "main-roll");
    ippAddInteger(col, IPP_TAG_ZERO, IPP_TAG_INTEGER, "media-top-margin", 0);
    ippAddString(col, IPP_TAG_ZERO, IPP_TAG_KEYWORD, "media-type", NULL, p->roll_type[0] ? p->roll_type : "stationery");
    ippAddCollection(attrs, IPP_TAG_PRINTER, "media-col-ready", col);
    ippDelete(size);
    ippDelete(col);
  }

  // print-rendering-intent: the RIP's ICC rendering intent (a vendor attribute to PAPPL)
  ippAddStrings(attrs, IPP_TAG_PRINTER, IPP_CONST_TAG(IPP_TAG_KEYWORD), "print-rendering-intent-supported", 5, NULL, intents);
  ippAddString(attrs, IPP_TAG_PRINTER, IPP_CONST_TAG(IPP_TAG_KEYWORD), "print-rendering-intent-default", NULL, "auto");
  // one-sided: the back side is never printed; no preferred-attributes answers
  ippAddString(attrs, IPP_TAG_PRINTER, IPP_CONST_TAG(IPP_TAG_KEYWORD), "pwg-raster-document-sheet-back", NULL, "normal");
  ippAddBoolean(attrs, IPP_TAG_PRINTER, "preferred-attributes-supported", 0);
  return (attrs);
}


static void fill_media(wp_printer_t *p, pappl_pr_driver_data_t *d);

static void
publish(wp_printer_t *p)		// the paper and the state in words, to PAPPL
{
  pappl_pr_driver_data_t	data;
  ipp_t				*attrs = extra_attrs(p);

  if (p->message[0])
  {
    char alert[256];
    bool critical = !strcmp(p->state, "fault") || !strcmp(p->state, "offline");
    // the roll running low is a warning (PWG 5100.9 printer-alert: its severity; the
    // Printer MIB's alert code for a supply of input media running low)
    snprintf(alert, sizeof(alert), "code=%s;severity=%s;group=other;",
             p->paused ? "stopped" : !critical && strstr(p->reasons, "media-low") ? "inputMediaSupplyLow" : "other",
             critical ? "critical" : "warning");
    ippAddOctetString(attrs, IPP_TAG_PRINTER, "printer-alert", alert, (int)strlen(alert));
    ippAddString(attrs, IPP_TAG_PRINTER, IPP_TAG_TEXT, "printer-alert-description", NULL, p->message);
  }
  papplPrinterGetDriverData(p->printer, &data);
  fill_media(p, &data);
  papplPrinterSetDriverData(p->printer, &data, attrs);
  ippDelete(attrs);
}


static void
media_update(char **f, int n)		// media NAME WIDTH_MM LENGTH_MM [ROLL_MEDIA [TYPES]]
{
  wp_printer_t	*p;
  int		width, length, num_types = 0;
  char		types[WP_MAX_TYPES][64], roll_type[64] = "", list[1024], *t, *save = NULL;
  bool		same_types;

  if (n < 4 || (p = find_printer(f[1])) == NULL || !p->printer)
    return;
  width  = atoi(f[2]);
  length = atoi(f[3]);
  if (width < 25 || width > p->print_mm || length < 0)
    return;				// not a paper this printer can hold: keep what was said
  if (n >= 5)
    papplCopyString(roll_type, f[4], sizeof(roll_type));
  if (n >= 6)				// the library: media names, comma separated
  {
    papplCopyString(list, f[5], sizeof(list));
    for (t = strtok_r(list, ",", &save); t && num_types < WP_MAX_TYPES; t = strtok_r(NULL, ",", &save))
      if (*t)
        papplCopyString(types[num_types ++], t, sizeof(types[0]));
  }
  else
  {
    num_types = p->num_types;
    memcpy(types, p->types, sizeof(types));
  }
  same_types = num_types == p->num_types && !memcmp(types, p->types, sizeof(types[0]) * (size_t)num_types);
  if (width == p->roll_mm && length == p->roll_len_mm && !strcmp(roll_type, p->roll_type) && same_types)
    return;
  p->roll_mm     = width;
  p->roll_len_mm = length;
  papplCopyString(p->roll_type, roll_type, sizeof(p->roll_type));
  p->num_types = num_types;
  memcpy(p->types, types, sizeof(types));
  publish(p);
}


static void
printer_update(char **f, int n)		// printer NAME STATE PAUSED REASONS MESSAGE
{
  wp_printer_t	*p;
  int		paused;
  bool		message_changed;
  pappl_preason_t bits;

  if (n < 6 || (p = find_printer(f[1])) == NULL || !p->printer)
    return;
  paused = atoi(f[3]);
  message_changed = strcmp(p->message, f[5]) != 0;
  bits = reason_bits(f[4]);
  papplPrinterSetReasons(p->printer, bits, WP_REASONS & ~bits);
  if (paused && !p->paused)
    papplPrinterPause(p->printer);	// no new IPP job starts while the printer is paused
  else if (!paused && p->paused)
    papplPrinterResume(p->printer);
  papplCopyString(p->state, f[2], sizeof(p->state));
  papplCopyString(p->reasons, f[4], sizeof(p->reasons));
  p->paused = paused;
  if (message_changed)
  {
    papplCopyString(p->message, f[5], sizeof(p->message));
    publish(p);
  }
}


static void
job_update(char **f, int n)		// job TAG WPID STATE COPIES_DONE COPIES STROKES_DONE STROKES_TOTAL MESSAGE
{
  wp_track_t *t;
  int tag;

  if (n < 9)
    return;
  tag = atoi(f[1]);
  pthread_mutex_lock(&io_lock);
  for (t = tracks; t; t = t->next)
  {
    if (t->tag == tag)
    {
      t->wpid          = atoi(f[2]);
      papplCopyString(t->state, f[3], sizeof(t->state));
      t->copies_done   = atoi(f[4]);
      t->copies        = atoi(f[5]);
      t->strokes_done  = atoi(f[6]);
      t->strokes_total = atoi(f[7]);
      papplCopyString(t->message, f[8], sizeof(t->message));
      t->seq ++;
      pthread_cond_broadcast(&io_cond);
      break;
    }
  }
  pthread_mutex_unlock(&io_lock);
}


static void *
reader_thread(void *data)		// lines from the bridge; EOF: the bridge is gone, stop
{
  char	line[WP_LINE], *f[16], *end;
  int	n;

  (void)data;
  while (fgets(line, sizeof(line), stdin))
  {
    if ((end = strchr(line, '\n')) != NULL)
      *end = '\0';
    n = split_tabs(line, f, 16);
    if (!strcmp(f[0], "printer"))
      printer_update(f, n);
    else if (!strcmp(f[0], "media"))
      media_update(f, n);
    else if (!strcmp(f[0], "job"))
      job_update(f, n);
    else if (!strcmp(f[0], "quit"))
      break;
  }
  papplSystemShutdown(wp_system);
  pthread_mutex_lock(&io_lock);
  pthread_cond_broadcast(&io_cond);
  pthread_mutex_unlock(&io_lock);
  return (NULL);
}


// -- authentication: the API's token ----------------------------------------------------------

static http_status_t
unauthorized(pappl_client_t *client)	// 401, after reading what the client is still sending
{
  // PAPPL answers "100 Continue" before it reads the IPP request, so a client printing a
  // document is still sending it when the 401 goes out; reading the rest of the document
  // first lets the client see the 401 and repeat the request with its credentials (else a
  // large document meets a closed connection: "Unable to finish request").  Only requests
  // that carry a document: flushing one without made ipptool retry without credentials.
  ipp_op_t op = papplClientGetOperation(client);

  if (op == IPP_OP_PRINT_JOB || op == IPP_OP_SEND_DOCUMENT)
    httpFlush(papplClientGetHTTP(client));
  return (HTTP_STATUS_UNAUTHORIZED);
}


static http_status_t
auth_cb(pappl_client_t *client, const char *group, gid_t groupid, void *cb_data)
{
  const char	*authorization = httpGetField(papplClientGetHTTP(client), HTTP_FIELD_AUTHORIZATION);
  char		userpass[512], *password;
  int		len = (int)sizeof(userpass);
  size_t	i, tlen = strlen(wp.token), plen;
  unsigned char	diff = 0;

  (void)group;
  (void)groupid;
  (void)cb_data;

  if (!authorization || strncmp(authorization, "Basic ", 6))
  {
    papplLogClient(client, PAPPL_LOGLEVEL_DEBUG, "No Basic authorization (%s).", authorization ? authorization : "none");
    return (unauthorized(client));
  }
  for (authorization += 6; *authorization == ' '; authorization ++);
  httpDecode64_2(userpass, &len, authorization);
  userpass[len >= 0 && len < (int)sizeof(userpass) ? len : (int)sizeof(userpass) - 1] = '\0';
  if ((password = strchr(userpass, ':')) == NULL)
    return (unauthorized(client));
  password ++;
  plen = strlen(password);
  // constant time in the token's length
  for (i = 0; i < tlen; i ++)
    diff |= (unsigned char)(wp.token[i] ^ (i < plen ? password[i] : 0));
  if (diff || plen != tlen)
    return (unauthorized(client));
  return (HTTP_STATUS_CONTINUE);
}


// -- the driver -------------------------------------------------------------------------------

static const char *
mime_cb(const unsigned char *header, size_t headersize, void *data)	// auto-typing beyond PAPPL's
{
  (void)data;
  if (headersize >= 4 && (!memcmp(header, "II*\0", 4) || !memcmp(header, "MM\0*", 4)))
    return ("image/tiff");
  if (headersize >= 4 && !memcmp(header, "\305\320\323\306", 4))	// DOS EPS binary header
    return ("application/postscript");
  return ("application/octet-stream");		// the RIP detects by content (docs/documents.md)
}


static void
add_media(wp_printer_t *p, pappl_pr_driver_data_t *d, const char *name)
{
  if (p->num_media < 16 && d->num_media < PAPPL_MAX_MEDIA)
  {
    papplCopyString(p->media_names[p->bank][p->num_media], name, sizeof(p->media_names[0][0]));
    d->media[d->num_media ++] = p->media_names[p->bank][p->num_media ++];
  }
}


//
// 'fill_media()' - The media a printer offers, from the paper loaded (docs/ipp.md "The paper").
//
// The paper's width is the printer's measurement (its edge sensors, via the server), else
// the profile's paper until the first measurement; its length is the remaining length of
// the roll the server tracks, or unknown.  Offered: the standard sizes the paper is wide
// enough for, and any size from 25 x 25 mm up to the paper's width by the longest print
// (or the roll left).  The default is the roll itself - never a sheet size: CUPS fits jobs
// to the default - and the ready medium is the roll (extra_attrs() when its length is unknown).
//

static void
fill_media(wp_printer_t *p, pappl_pr_driver_data_t *d)
{
  char	name[64];
  int	i, length = p->roll_len_mm > 0 && p->roll_len_mm < p->max_length_mm ? p->roll_len_mm : p->max_length_mm;
  static const struct { const char *name; int w, l; } sizes[] =
  {					// standard sizes offered when the roll is wide enough
    { "na_index-4x6_4x6in", 102, 152 },
    { "iso_a4_210x297mm", 210, 297 },
    { "na_letter_8.5x11in", 216, 279 },
    { "iso_a3_297x420mm", 297, 420 },
    { "na_ledger_11x17in", 279, 432 },
    { "iso_a2_420x594mm", 420, 594 },
    { "iso_a1_594x841mm", 594, 841 },
    { "na_arch-e_36x48in", 914, 1219 },
    { "iso_a0_841x1189mm", 841, 1189 },
    { "iso_2a0_1189x1682mm", 1189, 1682 }
  };

  p->bank      = !p->bank;		// PAPPL may be reading the other bank right now
  p->num_media = 0;
  d->num_media = 0;
  for (i = 0; i < (int)(sizeof(sizes) / sizeof(sizes[0])); i ++)
    if (sizes[i].w <= p->roll_mm && sizes[i].l <= length)
      add_media(p, d, sizes[i].name);
  snprintf(name, sizeof(name), "roll_max_%dx%dmm", p->roll_mm, length);
  add_media(p, d, name);
  snprintf(name, sizeof(name), "roll_min_%dx%dmm", 25, 25);
  add_media(p, d, name);

  // media-type: stationery, then the media library's entries (a job's media-col media-type
  // naming one prints with that media: app/ipp/bridge.py)
  d->num_type = 0;
  papplCopyString(p->type_names[p->bank][0], "stationery", sizeof(p->type_names[0][0]));
  d->type[d->num_type ++] = p->type_names[p->bank][0];
  for (i = 0; i < p->num_types && d->num_type < WP_MAX_TYPES && d->num_type < PAPPL_MAX_TYPE; i ++)
  {
    papplCopyString(p->type_names[p->bank][d->num_type], p->types[i], sizeof(p->type_names[0][0]));
    d->type[d->num_type] = p->type_names[p->bank][d->num_type];
    d->num_type ++;
  }

  d->num_source = 1;
  d->source[0]  = "main-roll";
  memset(&d->media_ready[0], 0, sizeof(d->media_ready[0]));
  if (p->roll_len_mm > 0)		// a tracked roll: its width and what is left of it
    snprintf(d->media_ready[0].size_name, sizeof(d->media_ready[0].size_name), "roll_main-roll_%dx%dmm", p->roll_mm, p->roll_len_mm);
  d->media_ready[0].size_width   = p->roll_mm * 100;
  d->media_ready[0].size_length  = p->roll_len_mm * 100;
  d->media_ready[0].left_margin  = d->media_ready[0].right_margin = p->margin_hmm;
  papplCopyString(d->media_ready[0].source, "main-roll", sizeof(d->media_ready[0].source));
  papplCopyString(d->media_ready[0].type, p->roll_type[0] ? p->roll_type : "stationery", sizeof(d->media_ready[0].type));

  // the default: the roll, as wide as the paper, as long as a print may be
  memset(&d->media_default, 0, sizeof(d->media_default));
  snprintf(d->media_default.size_name, sizeof(d->media_default.size_name), "roll_main-roll_%dx%dmm", p->roll_mm, length);
  d->media_default.size_width  = p->roll_mm * 100;
  d->media_default.size_length = length * 100;
  d->media_default.left_margin = d->media_default.right_margin = p->margin_hmm;
  papplCopyString(d->media_default.source, "main-roll", sizeof(d->media_default.source));
  papplCopyString(d->media_default.type, p->roll_type[0] ? p->roll_type : "stationery", sizeof(d->media_default.type));
}


static bool
driver_cb(pappl_system_t *system, const char *driver_name, const char *device_uri,
          const char *device_id, pappl_pr_driver_data_t *d, ipp_t **driver_attrs, void *cbdata)
{
  wp_printer_t	*p;
  int		i;

  (void)system;
  (void)driver_name;
  (void)device_id;
  (void)cbdata;

  // device URI: wideprint:///NAME
  if (strncmp(device_uri, "wideprint:///", 13) || (p = find_printer(device_uri + 13)) == NULL)
    return (false);

  d->printfile_cb   = print_file_cb;
  d->rstartjob_cb   = raster_start_job;
  d->rstartpage_cb  = raster_start_page;
  d->rwriteline_cb  = raster_write_line;
  d->rendpage_cb    = raster_end_page;
  d->rendjob_cb     = raster_end_job;
  d->format         = "image/tiff";	// printed as it is, like every other format
  papplCopyString(d->make_and_model, p->make_model, sizeof(d->make_and_model));
  d->ppm            = 1;
  d->ppm_color      = 1;
  d->kind           = PAPPL_KIND_DOCUMENT | PAPPL_KIND_PHOTO | PAPPL_KIND_ROLL;
  d->has_supplies   = false;
  d->input_face_up  = true;
  d->output_face_up = true;
  d->orient_default = IPP_ORIENT_PORTRAIT;
  d->color_supported = PAPPL_COLOR_MODE_AUTO | PAPPL_COLOR_MODE_COLOR;
  d->color_default  = PAPPL_COLOR_MODE_AUTO;
  d->content_default = PAPPL_CONTENT_AUTO;
  d->quality_default = IPP_QUALITY_NORMAL;
  d->scaling_default = PAPPL_SCALING_NONE;
  d->raster_types   = PAPPL_PWG_RASTER_TYPE_SRGB_8 | PAPPL_PWG_RASTER_TYPE_SGRAY_8;
  d->force_raster_type = PAPPL_PWG_RASTER_TYPE_NONE;
  d->duplex         = PAPPL_DUPLEX_NONE;
  d->sides_supported = PAPPL_SIDES_ONE_SIDED;
  d->sides_default  = PAPPL_SIDES_ONE_SIDED;
  d->finishings     = PAPPL_FINISHINGS_NONE;

  // printer-resolution: the dpi modes (scan direction; the RIP resamples to the device grid)
  d->num_resolution = p->num_dpi < PAPPL_MAX_RESOLUTION ? p->num_dpi : PAPPL_MAX_RESOLUTION;
  for (i = 0; i < d->num_resolution; i ++)
    d->x_resolution[i] = d->y_resolution[i] = p->dpi[i];
  d->x_default = d->y_default = p->default_dpi;

  // margins: the profile's side margins; none along the roll
  d->borderless = false;
  d->left_right = p->margin_hmm;
  d->bottom_top = 0;

  fill_media(p, d);

  // Identify-Printer: the message goes to the server's log (the operator's screen)
  d->identify_cb        = identify_cb;
  d->identify_supported = PAPPL_IDENTIFY_ACTIONS_DISPLAY;
  d->identify_default   = PAPPL_IDENTIFY_ACTIONS_DISPLAY;

  d->num_vendor = 1;
  d->vendor[0]  = "print-rendering-intent";
  *driver_attrs = extra_attrs(p);
  return (true);
}


// -- the links IPP clients show: the shop's web page -----------------------------------------

//
// 'web_page_cb()' - Send a browser to the print server's web page (docs/web.md).
//
// PAPPL's own web interface is off (the server's page is the one place a shop looks at its
// printers), but printer-more-info and printer-supply-info-uri still name PAPPL's pages
// "/NAME/" and "/NAME/supplies": those answer with a redirect to the server's page.  A
// "*" as the page's host (a server listening on every address) is the host the client used.
//

static bool
web_page_cb(pappl_client_t *client, void *data)
{
  char		url[1024];
  const char	*star = strstr(wp.web_url, "//*");

  (void)data;
  if (star)
    snprintf(url, sizeof(url), "%.*s//%s%s", (int)(star - wp.web_url), wp.web_url, papplClientGetHostName(client), star + 3);
  else
    papplCopyString(url, wp.web_url, sizeof(url));
  return (papplClientRespondRedirect(client, HTTP_STATUS_FOUND, url));
}


// -- main -------------------------------------------------------------------------------------

int
main(int argc, char *argv[])
{
  pappl_pr_driver_t	driver = { "wideprint", "wideprint roll printer", "MFG:wideprint;MDL:roll printer;CMD:PDF,JPEG,PNG,TIFF,PWGRaster;", NULL };
  pappl_soptions_t	options = PAPPL_SOPTIONS_MULTI_QUEUE;
  pthread_t		reader;
  bool			loopback;
  int			i;
  static const char * const formats[] =
  {
    "image/jpeg", "image/png", "application/pdf", "application/postscript",
    "application/octet-stream"
  };

  if (argc != 2)
  {
    fputs("Usage: wideprint-ipp CONFIG\n", stderr);
    return (2);
  }
  if (!load_config(argv[1]))
    return (2);
  signal(SIGPIPE, SIG_IGN);
  mkdir(wp.spool, 0700);

  loopback = !strcmp(wp.listen, "localhost") || !strcmp(wp.listen, "127.0.0.1") || !strcmp(wp.listen, "::1");
  if (loopback)
    options |= PAPPL_SOPTIONS_NO_TLS;	// TLS only matters beyond this machine

  wp_system = papplSystemCreate(options, wp.name, wp.port, "_print,_universal", wp.spool,
                                wp.log, wp.loglevel, NULL, false);
  if (!wp_system)
  {
    fprintf(stderr, "wideprint-ipp: cannot create the PAPPL system: %s\n", strerror(errno));
    return (1);
  }
  if (loopback)
    papplSystemSetDNSSDName(wp_system, NULL);	// no DNS-SD for a loopback-only system
  if (wp.hostname[0])
    papplSystemSetHostName(wp_system, wp.hostname);
  else if (loopback)
    papplSystemSetHostName(wp_system, "localhost");
  if (!papplSystemAddListeners(wp_system, !strcmp(wp.listen, "*") ? NULL : wp.listen))
  {
    fprintf(stderr, "wideprint-ipp: cannot listen on %s port %d: %s\n", wp.listen, wp.port, strerror(errno));
    return (1);
  }
  if (!strcmp(wp.auth, "token"))
    papplSystemSetAuthCallback(wp_system, "Basic", auth_cb, NULL);
  if (wp.version[0])
  {
    // printer-firmware-name/-string-version/-version: the wideprint that answers
    pappl_version_t version;

    memset(&version, 0, sizeof(version));
    papplCopyString(version.name, "wideprint", sizeof(version.name));
    papplCopyString(version.sversion, wp.version, sizeof(version.sversion));
    sscanf(wp.version, "%hu.%hu.%hu", version.version + 0, version.version + 1, version.version + 2);
    papplSystemSetVersions(wp_system, 1, &version);
  }

  papplDeviceAddScheme("wideprint", PAPPL_DEVTYPE_CUSTOM_LOCAL, NULL, dev_open, dev_close, dev_read, dev_write, dev_status, NULL);
  papplSystemSetPrinterDrivers(wp_system, 1, &driver, NULL, NULL, driver_cb, NULL);
  papplSystemSetMIMECallback(wp_system, mime_cb, NULL);
  // every format wideprint reads goes to its queue untouched (print_original)
  for (i = 0; i < (int)(sizeof(formats) / sizeof(formats[0])); i ++)
    papplSystemAddMIMEFilter(wp_system, formats[i], "image/tiff", print_original, NULL);

  for (i = 0; i < wp.num_printers; i ++)
  {
    wp_printer_t	*p = wp.printers + i;
    char		uri[1024], path[256], host[256], devuri[256];
    pappl_supply_t	ink[4] =
    {
      { PAPPL_SUPPLY_COLOR_CYAN, "Cyan Ink", true, -1, PAPPL_SUPPLY_TYPE_INK },
      { PAPPL_SUPPLY_COLOR_MAGENTA, "Magenta Ink", true, -1, PAPPL_SUPPLY_TYPE_INK },
      { PAPPL_SUPPLY_COLOR_YELLOW, "Yellow Ink", true, -1, PAPPL_SUPPLY_TYPE_INK },
      { PAPPL_SUPPLY_COLOR_BLACK, "Black Ink", true, -1, PAPPL_SUPPLY_TYPE_INK }
    };

    snprintf(devuri, sizeof(devuri), "wideprint:///%s", p->name);
    if ((p->printer = papplPrinterCreate(wp_system, 0, p->name, "wideprint", "MFG:wideprint;MDL:roll printer;", devuri)) == NULL)
    {
      fprintf(stderr, "wideprint-ipp: cannot create the printer %s: %s\n", p->name, strerror(errno));
      return (1);
    }
    if (loopback)
      papplPrinterSetDNSSDName(p->printer, NULL);	// nothing to announce: no one else can reach it
    else
    {
      // the name print dialogs list (docs/ipp.md "DNS-SD"): "left - WP-3400 ...", at most
      // 63 bytes (a DNS label), not cut inside a UTF-8 character
      char	dnssd[64];
      size_t	len, lead;
      unsigned char c;

      snprintf(dnssd, sizeof(dnssd), "%s - %s", p->name, p->make_model[0] ? p->make_model : "wideprint");
      len = strlen(dnssd);
      for (lead = len; lead > 0 && ((unsigned char)dnssd[lead - 1] & 0xC0) == 0x80; lead --);
      if (lead > 0)
      {
        c = (unsigned char)dnssd[lead - 1];	// the last character's first byte
        if ((c >= 0xC0 && len - (lead - 1) < 2) || (c >= 0xE0 && len - (lead - 1) < 3) || (c >= 0xF0 && len - (lead - 1) < 4))
          dnssd[lead - 1] = '\0';		// cut inside it: drop it
      }
      papplPrinterSetDNSSDName(p->printer, dnssd);
    }
    papplPrinterSetSupplies(p->printer, 4, ink);	// ink levels: unknown (-1)
    papplPrinterSetMaxActiveJobs(p->printer, 0);
    papplPrinterSetMaxCompletedJobs(p->printer, 100);
    papplPrinterGetPath(p->printer, NULL, path, sizeof(path));
    if (wp.web_url[0])
    {
      char web[300];

      snprintf(web, sizeof(web), "%s/", path);		// printer-more-info
      papplSystemAddResourceCallback(wp_system, web, "text/html", web_page_cb, NULL);
      snprintf(web, sizeof(web), "%s/supplies", path);	// printer-supply-info-uri
      papplSystemAddResourceCallback(wp_system, web, "text/html", web_page_cb, NULL);
    }
    papplSystemGetHostName(wp_system, host, sizeof(host));
    // the web path is "/NAME"; the IPP resource is "/ipp/print/NAME"
    snprintf(uri, sizeof(uri), "ipp://%s:%d/ipp/print%s", host, papplSystemGetHostPort(wp_system), path);
    send_line("uri\t%s\t%s", p->name, uri);
  }

  pthread_create(&reader, NULL, reader_thread, NULL);
  send_line("ready");
  papplSystemRun(wp_system);
  papplSystemDelete(wp_system);
  return (0);
}
