<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>
<qgis version="3.28.0-Firenze" styleCategories="Symbology">
  <pipe>
    <provider>
      <resampling enabled="false" maxOversampling="2" zoomedOutResamplingMethod="nearestNeighbour" zoomedInResamplingMethod="nearestNeighbour"/>
    </provider>
    <rasterrenderer opacity="1" band="1" alphaBand="-1" nodataColor="" type="paletted">
      <colorPalette>
        <paletteEntry value="0" color="#ffffff" alpha="0" label="soil"/>
        <paletteEntry value="1" color="#4daf4a" alpha="255" label="vegetation (not gridded)"/>
        <paletteEntry value="2" color="#984ea3" alpha="255" label="objects by classification (not gridded)"/>
        <paletteEntry value="3" color="#999999" alpha="255" label="other points: noise, water, unclassified (not gridded)"/>
        <paletteEntry value="4" color="#ff7f00" alpha="255" label="moved object (left out of the volumes)"/>
        <paletteEntry value="5" color="#e41a1c" alpha="255" label="object in one survey only (counted)"/>
        <paletteEntry value="6" color="#a6d854" alpha="255" label="rough change: vegetation? (counted, in the interval)"/>
      </colorPalette>
      <colorramp type="randomcolors" name="[source]"/>
    </rasterrenderer>
    <brightnesscontrast brightness="0" contrast="0" gamma="1"/>
    <huesaturation saturation="0" colorizeOn="0" colorizeRed="255" colorizeGreen="128" colorizeBlue="128" colorizeStrength="100" grayscaleMode="0"/>
    <rasterresampler maxOversampling="2"/>
  </pipe>
  <blendMode>0</blendMode>
</qgis>
