// The C interface of the image plugin (libterrain_image_oiio.so, image_oiio_plugin.cpp), the only
// binary that links OpenImageIO: its ~260 shared libraries would otherwise be mapped into every
// process at start-up. libpyramid dlopens it on the first image read or write (image_plugin.cpp).
// Plain C types only, so the two sides share no C++ ABI; no exception crosses it.
//
// Every function that can fail returns TERRAIN_IMAGE_OK or another status, and then writes
// OpenImageIO's reason (NUL-terminated, truncated to message_size) into `message`.
// Raise TERRAIN_IMAGE_PLUGIN_ABI_VERSION on any change to what is declared here.
#pragma once

#include <stddef.h>
#include <stdint.h>

#define TERRAIN_IMAGE_PLUGIN_ABI_VERSION 3

#ifdef __cplusplus
extern "C" {
#endif

enum terrain_image_status {
  TERRAIN_IMAGE_OK = 0,
  TERRAIN_IMAGE_OPEN_FAILED = 1,    // no reader for the file, or it cannot be opened / decoded
  TERRAIN_IMAGE_READ_FAILED = 2,    // a row range could not be decoded
  TERRAIN_IMAGE_NO_WRITER = 3,      // no writer for the file name's extension
  TERRAIN_IMAGE_CREATE_FAILED = 4,  // the writer could not create the file
  TERRAIN_IMAGE_WRITE_FAILED = 5,   // writing rows or closing the file failed
  TERRAIN_IMAGE_BAD_ARGUMENT = 6,   // unknown pixel type, or a handle that is null
};

// Pixel types as stored or requested. TERRAIN_PIXEL_OTHER: anything else (header only).
enum terrain_image_pixel {
  TERRAIN_PIXEL_OTHER = 0,
  TERRAIN_PIXEL_UINT8 = 1,
  TERRAIN_PIXEL_INT8 = 2,
  TERRAIN_PIXEL_UINT16 = 3,
  TERRAIN_PIXEL_INT16 = 4,
  TERRAIN_PIXEL_UINT32 = 5,
  TERRAIN_PIXEL_INT32 = 6,
  TERRAIN_PIXEL_HALF = 7,
  TERRAIN_PIXEL_FLOAT = 8,
  TERRAIN_PIXEL_DOUBLE = 9,
};

struct terrain_image_header {
  int32_t width, height, depth, channels;
  int32_t pixel;        // enum terrain_image_pixel of the stored samples
  char pixel_name[32];  // OpenImageIO's name of the stored type ("uint8", "half", ...), for messages
  // Bytes OpenImageIO must hold at once to decode any one row: a strip or a row of tiles as the file
  // groups them, the whole image for an interlaced PNG. From the header, before any allocation.
  int64_t decode_unit_bytes;
};

typedef struct terrain_image_reader terrain_image_reader;
typedef struct terrain_image_writer terrain_image_writer;

int32_t terrain_image_abi_version(void);

// Opens `path` (RGB kept as stored: alpha is not premultiplied) and fills `header`. An error that
// OpenImageIO records while opening is a failure even when it returns an input.
int32_t terrain_image_open(const char* path, terrain_image_reader** reader,
                           struct terrain_image_header* header, char* message, size_t message_size);
// Decodes rows [row_begin, row_end) (0 = first row), `channels` channels from the first, converted
// to `pixel`, into `pixels` (row_end - row_begin rows of width * channels samples, packed).
int32_t terrain_image_read_rows(terrain_image_reader* reader, int32_t row_begin, int32_t row_end,
                                int32_t channels, int32_t pixel, void* pixels, char* message,
                                size_t message_size);
void terrain_image_close(terrain_image_reader* reader);

// The GeoTIFF tags of an opened TIFF as stored (version 2), read with libtiff/libgeotiff; the reader
// (libreaders' io_image.cpp) interprets and validates them. Counts are those of the file, the arrays
// hold their first values. For a file that is not a TIFF every count and flag is 0.
#define TERRAIN_IMAGE_CITATION_SIZE 8192
struct terrain_image_georef {
  int32_t pixel_scale_count;  // ModelPixelScaleTag (33550) values; pixel_scale holds up to 3
  double pixel_scale[3];
  int32_t tiepoint_count;  // ModelTiepointTag (33922) values (6 per tiepoint); tiepoint: the first
  double tiepoint[6];
  int32_t transformation_count;  // ModelTransformationTag (34264) values; 16 when present
  double transformation[16];
  int32_t has_geokeys;         // GeoKeyDirectoryTag (34735) present
  int32_t model_type;          // GTModelTypeGeoKey (1 projected, 2 geographic, 3 geocentric); 0 absent
  int32_t raster_type;         // GTRasterTypeGeoKey (1 PixelIsArea, 2 PixelIsPoint); 0 absent
  int32_t geographic_type;     // GeographicTypeGeoKey (EPSG code, 32767 user-defined); 0 absent
  int32_t projected_type;      // ProjectedCSTypeGeoKey (EPSG code, 32767 user-defined); 0 absent
  int32_t citation_truncated;  // 1 when the citation below did not fit
  char citation[TERRAIN_IMAGE_CITATION_SIZE];  // PCSCitation, else GeogCitation, else GTCitation;
                                               // NUL-terminated
  int32_t has_nodata;                          // GDAL_NODATA (42113) present
  char nodata[64];                             // its text, NUL-terminated (truncated)
};
int32_t terrain_image_read_georef(terrain_image_reader* reader, struct terrain_image_georef* georef,
                                  char* message, size_t message_size);

// Bit of terrain_image_create's flags: write an empty DateTime (otherwise some writers stamp the
// current time), so that the output is byte-reproducible.
#define TERRAIN_IMAGE_NO_TIMESTAMP 1

// Creates `path` (the writer is chosen by its extension) for width x height pixels of `channels`
// samples of type `pixel`; `compression` may be NULL for the writer's default.
int32_t terrain_image_create(const char* path, int32_t width, int32_t height, int32_t channels, int32_t pixel,
                             const char* compression, int32_t flags, terrain_image_writer** writer,
                             char* message, size_t message_size);
// Writes rows [row_begin, row_end), packed like terrain_image_read_rows' output.
int32_t terrain_image_write_rows(terrain_image_writer* writer, int32_t row_begin, int32_t row_end,
                                 const void* pixels, char* message, size_t message_size);
// Completes the file; the writer must still be destroyed.
int32_t terrain_image_finish(terrain_image_writer* writer, char* message, size_t message_size);
void terrain_image_destroy(terrain_image_writer* writer);

#ifdef __cplusplus
}
#endif
